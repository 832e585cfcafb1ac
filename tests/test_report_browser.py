"""Every command's ``report.html`` rendered from disk in a real headless browser.

``servo run``, ``frf``, ``loop``, ``diagnose``, ``compensate`` and ``fleet diagnose``
each write their folder once (a module fixture); one chromium process then opens an index
page that frames every ``report.html`` from ``file://`` with the network cut off
(``--host-resolver-rules``: every host unresolvable) and reads back, per page, the
summary band's text and status, the whole visible text, every image's natural size and
the resources the page fetched.  Each test checks that what the browser shows is what
the command's JSON holds: the verdict or headline figures, the figures of its tables,
every image decoded (``naturalWidth > 0`` and drawn, as many as the PNGs the command wrote), and
nothing loaded from outside the page.  Debian's ``chromium`` is required: CI installs it
(``.ci/run``), so a machine without it fails here rather than skipping.
"""
import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from servo.cli import main
from servo.io.page import number
from tests.test_page import self_contained

pytestmark = pytest.mark.slow  # six commands (a diagnosis, a fleet on Dask, a loop measurement) and a browser

ROOT = Path(__file__).resolve().parents[1]
EMPS = ROOT.parent / "shared" / "data" / "emps" / "DATA_EMPS.mat"
COMMANDS = ("run", "frf", "loop", "diagnose", "compensate", "fleet")

#: the index page: each report in a frame; on load (after every frame and its images),
#: what each shows, as JSON in #result
INDEX = """<!DOCTYPE html><html><head><meta charset=utf-8></head><body><pre id=result>pending</pre>
{frames}
<script>
// the share of an image's pixels, drawn at 64 x 64, that are opaque and not white: a plot
// has axes, text and lines; an image the browser could not decode draws nothing
function drawn(img) {{
  const c = document.createElement("canvas");
  c.width = c.height = 64;
  const g = c.getContext("2d");
  g.drawImage(img, 0, 0, 64, 64);
  const p = g.getImageData(0, 0, 64, 64).data;
  let n = 0;
  for (let k = 0; k < p.length; k += 4) if (p[k + 3] > 200 && p[k] + p[k + 1] + p[k + 2] < 600) n++;
  return n / (64 * 64);
}}
window.addEventListener("load", () => {{
  try {{
    const out = {{}};
    for (const f of document.querySelectorAll("iframe")) {{
      const d = f.contentDocument, s = d.getElementById("summary");
      out[f.dataset.name] = {{title: d.title, summary: s.innerText, status: s.dataset.status, text: d.body.innerText,
        images: [...d.images].map(i => [i.complete, i.naturalWidth, i.naturalHeight, drawn(i)]),
        fetched: f.contentWindow.performance.getEntriesByType("resource").map(e => e.name)}};
    }}
    document.getElementById("result").textContent = JSON.stringify(out);
  }} catch (e) {{ document.getElementById("result").textContent = "error: " + e; }}
}});
</script></body></html>
"""


def chromium() -> str:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        pytest.fail("chromium is not installed: `apt-get install chromium` (.ci/run installs it when it is missing)")
    return found


def browser(tmp: Path, *args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    """Headless chromium with no network, no GPU, a profile in ``tmp``."""
    cmd = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={tmp / 'profile'}", "--host-resolver-rules=MAP * ~NOTFOUND", *args]  # fmt: skip
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """The six commands' folders, each made through the CLI as a user would."""
    tmp = tmp_path_factory.mktemp("reports")
    o = {c: tmp / c for c in COMMANDS}
    syn = tmp / "syn"
    commands = [
        ["run", "--duration", "0.4", "--fast", "--out", o["run"]],
        ["frf", EMPS, "--columns", "u=vir,x=qm", "--scale", "u=gtau", "--force-unit", "N", "--out", o["frf"]],
        ["loop", "--n-freq", "8", "--periods", "4", "--out", o["loop"]],
        ["fleet", "synthetic", "--drives", "4", "--duration", "0.2", "--out", syn],
        ["diagnose", syn / "drive0000.npz", "--out", o["diagnose"]],
        ["compensate", o["diagnose"] / "report.json", "--config", o["diagnose"] / "final_model.toml", "--full",
         "--allow-worse", "--out", o["compensate"]],
        ["fleet", "diagnose", "--manifest", syn / "manifest.csv", "--workers", "1", "--out", o["fleet"]],
    ]  # fmt: skip
    for argv in commands:
        assert main([str(a) for a in argv] + ["--quiet"]) == 0, argv
    return o


@pytest.fixture(scope="module")
def shown(outputs, tmp_path_factory):
    """What the browser shows of each command's page (one browser start for all)."""
    tmp = tmp_path_factory.mktemp("browser")
    frames = "\n".join(f'<iframe data-name="{c}" src="{(outputs[c] / "report.html").as_uri()}"></iframe>' for c in COMMANDS)
    index = tmp / "index.html"
    index.write_text(INDEX.format(frames=frames), encoding="utf-8")
    r = browser(tmp, "--allow-file-access-from-files", "--dump-dom", index.as_uri())
    m = re.search(r'<pre id="result">(.*?)</pre>', r.stdout, re.S)
    assert r.returncode == 0 and m, r.stderr[-2000:]
    text = html.unescape(m.group(1))
    assert text.startswith("{"), text[:500]
    return json.loads(text)


def _json(outputs, command: str) -> dict:
    name = {"diagnose": "report.json", "fleet": "fleet.json"}.get(command, "summary.json")
    return json.loads((outputs[command] / name).read_text())


@pytest.mark.parametrize("command", COMMANDS)
def test_the_page_is_listed_self_contained_and_every_image_shows(outputs, shown, command):
    page = shown[command]
    data = _json(outputs, command)
    assert "report.html" in data["files"]
    self_contained((outputs[command] / "report.html").read_text(encoding="utf-8"))
    assert page["fetched"] == [], page["fetched"]  # nothing loaded from outside the page (data: URIs are not fetched)
    pngs = 1 if command == "compensate" else len(list(outputs[command].glob("*.png")))  # compensate: the check's plot
    assert len(page["images"]) == pngs >= 1
    assert all(done and w > 50 and h > 50 and 0.005 < ink < 0.9 for done, w, h, ink in page["images"]), page["images"]
    prov = data.get("provenance") or {}
    assert page["title"] == f"servo {'fleet diagnose' if command == 'fleet' else command}"
    assert prov.get("servo_version") is None or prov["servo_version"] in page["text"]
    # the summary comes first: the page's visible text opens with the title, then the summary band
    assert page["text"].index(page["summary"].splitlines()[0]) < page["text"].index("Provenance" if prov else "Run")


def test_run_page_shows_the_summary_figures(outputs, shown):
    s, page = _json(outputs, "run"), shown["run"]
    for label, r in s["runs"].items():
        assert f"{label}: tracking error RMS {r['error_rms_m'] * 1e9:.1f} nm" in page["summary"]
        for seg, v in r["error_rms_by_segment_m"].items():
            assert f"{seg}\t" in page["text"] and number(v * 1e9, 5) in page["text"]
        for st in r["steps"]:
            settle = "never" if st["settling_ms"] is None else number(st["settling_ms"])
            assert number(st["overshoot_pct"]) in page["text"] and settle in page["text"]
    assert f"{s['ticks']} ticks" in page["summary"] and s["provenance"]["config_sha256"] in page["text"]


def test_frf_page_shows_the_coherent_band(outputs, shown):
    s, page = _json(outputs, "frf"), shown["frf"]
    c = s["coherent"]
    assert page["status"] == ("ok" if c["points"] else "warn")
    assert f"{c['points']} of {c['of']} points, {c['f_lo_hz']:.4g}-{c['f_hi_hz']:.4g} Hz" in page["summary"]
    assert s["unit"] == "m/N" and "H in m/N" in page["summary"]
    assert str(s["welch"]["nperseg"]) in page["text"] and s["provenance"]["inputs"][str(EMPS)] in page["text"]


def test_loop_page_shows_the_margins(outputs, shown):
    s, page = _json(outputs, "loop"), shown["loop"]
    for e in s["runs"]:
        m = e["margins"]
        assert f"crossover {m['crossover_hz']:.1f} Hz, phase margin {m['phase_margin_deg']:.1f} deg" in page["summary"]
        assert number(m["phase_margin_deg"]) in page["text"] and number(m["max_S_db"]) in page["text"]
    for w in s.get("warnings", []):
        assert f"warning: {w}" in page["summary"]
    assert page["status"] == ("warn" if s.get("warnings") else "ok")
    for name, m in s["designs"].items():
        assert f"design, {name}" in page["text"] and number(m["phase_margin_deg"]) in page["text"]


def test_diagnose_page_shows_the_verdict_first(outputs, shown):
    r, page = _json(outputs, "diagnose"), shown["diagnose"]
    assert page["summary"].startswith(f"verdict: {r['verdict']}: {r['verdict_text']}")
    assert page["status"] == {"consistent": "ok", "explained": "ok", "unexplained": "warn"}.get(r["verdict"], "bad")
    before, after = r["baseline"]["error"]["test_force_rel_pct"], r["final_model"]["error"]["test_force_rel_pct"]
    assert f"held-out force error {before:.3g} % -> {after:.3g} %" in page["summary"]
    for t in r["final_model"]["terms"]:
        assert t["physics"] in page["text"]
    for f in r["findings"]:
        assert f["physics"] in page["text"]


def test_compensate_page_shows_the_proposal_and_the_check(outputs, shown):
    s, page = _json(outputs, "compensate"), shown["compensate"]
    assert f"proposed: the {s['proposed']} compensator" in page["summary"]
    c = s["check"]
    assert c is not None and c["figures"]
    if c["steps_worse_than_none"]:
        assert page["status"] == "bad" and page["summary"].startswith("REFUSED: ")
        assert "WARNING: worse than no compensator: " + "; ".join(c["steps_worse_than_none"]) in page["summary"]
    for name, f in c["figures"].items():
        for st in f["run"]["steps"]:
            settle = "never" if st["settling_ms"] is None else number(st["settling_ms"])
            assert name in page["text"] and number(st["overshoot_pct"]) in page["text"] and settle in page["text"]
    for k, v in s["section"].items():
        assert k in page["text"] and (not isinstance(v, float) or f"{v:.4g}" in page["text"])


def test_fleet_page_shows_the_counts_and_the_flagged_drives(outputs, shown):
    s, page = _json(outputs, "fleet"), shown["fleet"]
    assert f"{s['drives']} drives, {s['ok']} ok, {s['failed']} failed" in page["summary"]
    assert f"flagged drives (findings, or verdict unexplained/out_of_scope): {len(s['flagged'])}" in page["summary"]
    assert f"robust outliers (|z| > {s['outlier_threshold']:g}): {len(s['outliers'])}" in page["summary"]
    truth = json.loads((outputs["fleet"].parent / "syn" / "truth.json").read_text())
    assert s["flagged"], truth  # the synthetic set's defective drive
    for d in s["flagged"]:
        assert d in page["text"]
    for o in s["outliers"]:
        assert o["drive"] in page["text"] and number(o["z"]) in page["text"]


def test_a_screenshot_of_a_page_is_drawn(outputs, tmp_path):
    """The run's page drawn as an image by the browser, from disk with no network (the
    screenshot a reader sees): it is a PNG of the window's size, not blank."""
    shot = tmp_path / "run.png"
    r = browser(tmp_path, "--window-size=1200,1600", f"--screenshot={shot}", (outputs["run"] / "report.html").as_uri())
    assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
    from matplotlib.image import imread

    img = imread(shot)
    assert img.shape[:2] == (1600, 1200) and img[..., :3].std() > 0.05  # text and plots, not a blank page

"""The commands the docs pages show, run as written (parsed from the page, so page and
test cannot drift apart), each checked against what its page states, over the whole
stated range."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from servo.config import Config
from servo.io.frequency_response import load_frequency_responses
from tests.helpers import SHARED, doc_commands, run_doc_command

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_frf_recipe_measures_the_compensated_drive_as_a_double_integrator(tmp_path, monkeypatch):
    """docs/frf.md: at every coherent line of 20-500 Hz, |H| J w^2 = 1 within 5 % and the
    phase within 6 degrees of -180 (the recipe once estimated from the total current,
    the drive itself: 0.1 to 2)."""
    run, frf = [c for c in doc_commands("docs/frf.md") if "RECORDING" not in c]
    assert run.startswith("servo run") and frf.startswith("servo frf")
    monkeypatch.chdir(tmp_path)
    assert run_doc_command(run) == 0
    assert run_doc_command(frf) == 0
    out = next(p for p in tmp_path.iterdir() if p.is_dir() and (p / "frf.npz").exists())
    (label, resp), = load_frequency_responses(out / "frf.npz").items()
    f = resp.f_hz
    m = (f >= 20) & (f <= 500) & (resp.coherence >= 0.9)
    assert m.sum() >= 90  # the multisine's 97 lines, 5 Hz apart: nearly all coherent
    J = Config().drive.J
    ratio = np.abs(resp.H[m]) * J * (2 * np.pi * f[m]) ** 2
    assert np.all(np.abs(ratio - 1) < 0.05), (ratio.min(), ratio.max())
    phase_from_minus_180 = np.degrees(np.angle(-resp.H[m]))
    assert np.all(np.abs(phase_from_minus_180) < 6.0), np.abs(phase_from_minus_180).max()
    summary = json.loads((out / "summary.json").read_text())
    assert summary  # written with the estimate


def _digits_tol(text: str) -> float:
    """Half a unit of the last digit written in ``text`` (``9.948e-4`` -> 5e-8)."""
    mant, _, exp = text.lower().partition("e")
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    return 0.5 * 10.0 ** (-decimals) * 10.0 ** (int(exp) if exp else 0)


def _close(value: float, text: str) -> bool:
    return abs(value - float(text)) <= _digits_tol(text) * 1.0001


def _servo_out(tmp_path, command: str) -> dict:
    """Run a documented command with no --out in ``tmp_path``; its summary.json."""
    assert run_doc_command(command + " --quiet") == 0
    (summary,) = (tmp_path / "servo-out").glob("*/summary.json")
    return json.loads(summary.read_text())


@pytest.mark.slow
def test_identify_simulate_reproduces_the_table_of_its_page(tmp_path, monkeypatch):
    """docs/identification.md, "The simulated square-wave experiment": every estimate of
    the robust path and of model (3) of the drive, to the digits the table writes; the
    relative error and the column-scaled condition number."""
    import re

    page = (ROOT / "docs" / "identification.md").read_text()
    (command,) = [c for c in doc_commands("docs/identification.md") if c.startswith("servo identify --simulate")]
    monkeypatch.chdir(tmp_path)
    summary = _servo_out(tmp_path, command)
    fit, model3_fit = summary["fits"]["robust"], summary["reference"]["model (3) of the drive"]["robust"]
    rows = re.findall(r"^\| (J|B|Fc|K|h0) \| ([-+0-9.e]+) \| [^|]+\| [^|]+\| ([-+0-9.e]+) \|", page, flags=re.M)
    assert [r[0] for r in rows] == ["J", "B", "Fc", "K", "h0"]
    for term, robust, model3 in rows:
        assert _close(fit["params"][term], robust), (term, fit["params"][term], robust)
        assert _close(model3_fit[term], model3), term
    rel, scaled = re.search(r"Relative error ([0-9.]+) %, condition number [^(]+\(column-scaled ([0-9.]+)\)", page).groups()
    assert _close(fit["rel_error_pct"], rel) and _close(fit["cond_scaled"], scaled)


@pytest.mark.slow
def test_hysteresis_simulate_reproduces_its_page(tmp_path, monkeypatch):
    """docs/identification.md, "The Dahl fit": sigma, Ha, alpha, the offset, the residual
    and the large loop's average slope, to the digits written."""
    import re

    page = (ROOT / "docs" / "identification.md").read_text()
    (command,) = [c for c in doc_commands("docs/identification.md") if c.startswith("servo hysteresis --simulate")]
    monkeypatch.chdir(tmp_path)
    s = _servo_out(tmp_path, command)
    m = re.search(r"sigma ([0-9.]+) A/m \([^)]+\), Ha ([0-9.]+) mA \([^)]+\), alpha ([0-9.]+) \([^)]+\), offset "
                  r"([0-9.]+) mA;\s+residual ([0-9.]+) % of the loop", page)  # fmt: skip
    sigma, Ha, alpha, c, residual = m.groups()
    d = s["dahl"]
    assert _close(d["params"]["sigma"], sigma) and _close(d["params"]["alpha"], alpha)
    assert _close(d["params"]["Ha"] * 1e3, Ha) and _close(d["params"]["c"] * 1e3, c)
    assert _close(d["rel_error_pct"], residual)
    K, half = re.search(r"K = ([0-9.]+) A/m \([^)]+\), half-height ([0-9.]+) mA", page).groups()
    assert _close(s["average_slope"]["params"]["K"], K) and _close(s["average_slope"]["params"]["Fc"] * 1e3, half)


DESIGN_ROWS = {"design, `1/(J s^2)`": "nominal 1/(J s^2)", "design, drive model, compensated": "drive model, compensated",
               "design, pivot small-signal, no compensator": "drive model, pivot small-signal, no comp."}  # fmt: skip


def _loop_table(page: str, title: str) -> list[list[str]]:
    """The rows (cells) of the first Markdown table after ``title`` on ``page``."""
    text = page[page.index(title):]
    rows = []
    for line in text.splitlines()[1:]:
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if not set(cells[0]) <= set("-") and cells[0] not in ("", "loop"):
                rows.append(cells)
        elif rows:
            break
    return rows


def _check_loop_rows(summary: dict, rows: list[list[str]]) -> None:
    import re

    measured = {e["label"]: e["margins"] for e in summary["runs"]}
    for cells in rows:
        label = cells[0]
        m = summary["designs"][DESIGN_ROWS[label]] if label in DESIGN_ROWS else measured[label]
        fc = re.match(r"([0-9.]+) Hz", cells[1]).group(1)
        pm = re.match(r"([0-9.]+) deg", cells[2]).group(1)
        assert _close(m["crossover_hz"], fc) and _close(m["phase_margin_deg"], pm), (label, m)
        if len(cells) > 3:
            if cells[3] == "none in band":
                assert m["gain_margin_db"] is None, label
            else:  # the binding one: "+4.3 dB upper at 6915 Hz"
                gm, side, f180 = re.match(r"([-+0-9.]+) dB (upper|lower) at ([0-9.]+) Hz", cells[3]).groups()
                assert _close(m["gain_margin_db"], gm) and m["gain_margin_side"] == side, (label, m)
                assert _close(m["gain_margin_hz"], f180), (label, m)


@pytest.mark.slow
def test_loop_page_table_is_what_servo_loop_measures(tmp_path):
    """docs/loop.md, "Measured (default drive, `servo loop --levels 0.2,4`)": every row's
    crossover, phase margin and gain margin, to the digits written."""
    page = (ROOT / "docs" / "loop.md").read_text()
    (command,) = [c for c in doc_commands("docs/loop.md") if c.startswith("servo loop --levels 0.2,4")]
    assert run_doc_command(f"{command} --quiet --out {tmp_path / 'loop'}") == 0
    summary = json.loads((tmp_path / "loop" / "summary.json").read_text())
    rows = _loop_table(page, "## Measured (default drive")
    assert len(rows) == 7
    _check_loop_rows(summary, rows)
    # "without it the crossover moves by +28 % at 0.2 mA and +20 % at 4 mA"
    assert [round(100 * s["shift_rel"]) for s in summary["crossover_shift"]] == [28, 20]


@pytest.mark.slow
def test_controllers_page_track_loop_is_the_design(tmp_path):
    """docs/controllers.md, "The paper's claim": the track kind's loop table."""
    page = (ROOT / "docs" / "controllers.md").read_text()
    (command,) = [c for c in doc_commands("docs/controllers.md") if c.startswith("servo loop")]
    assert run_doc_command(f"{command} --quiet --out {tmp_path / 'loop'}") == 0
    summary = json.loads((tmp_path / "loop" / "summary.json").read_text())
    rows = _loop_table(page, "## The paper's claim")
    assert len(rows) == 5
    for cells in rows:  # "187.0 Hz (+25 %)": the crossover, then its shift
        cells[1] = cells[1].split(" (")[0]
    _check_loop_rows(summary, rows)


@pytest.mark.slow
def test_controllers_page_plugin_command_runs_the_plugin(tmp_path, monkeypatch):
    """docs/controllers.md: `servo run --plugin my_pd ...` with the page's module in the
    current folder runs the PD kind with the gain the command sets."""
    import re

    from servo.controllers import KINDS

    page = (ROOT / "docs" / "controllers.md").read_text()
    (tmp_path / "my_pd.py").write_text(re.findall(r"^```python\n(.*?)^```", page, flags=re.S | re.M)[0])
    (command,) = [c for c in doc_commands("docs/controllers.md") if "--plugin my_pd" in c]
    monkeypatch.chdir(tmp_path)
    before = dict(KINDS)
    try:
        assert run_doc_command(f"{command} --fast --quiet --out {tmp_path / 'pd'}") == 0
        import servo

        run = servo.load_run(tmp_path / "pd")
    finally:
        KINDS.clear()
        KINDS.update(before)
    assert run.config.controller.kind == "pd" and run.config.controller.pd.kp == 300
    assert "de_dt" in run.logs["compensated"] and set(run.labels) == {"compensated", "uncompensated"}


@pytest.mark.slow
def test_hdd_page_runs_give_its_pes_table(tmp_path):
    """docs/hdd.md, "Through the runtime": both example configs, as written, print the
    page's PES 3 sigma, RRO p-p and NRRO 3 sigma (to the digits written)."""
    import re

    page = (ROOT / "docs" / "hdd.md").read_text()
    commands = [c for c in doc_commands("docs/hdd.md") if c.startswith("servo run --config examples/hdd-")]
    lines = {k: next(line for line in page.splitlines() if line.startswith("|") and f"(`{k}`)" in line)
             for k in ("nss", "track")}  # fmt: skip
    rows = {k: re.findall(r"\| ([0-9.]+) %", line) for k, line in lines.items()}
    assert len(commands) == 2 and all(len(r) == 3 for r in rows.values())
    for i, command in enumerate(commands):
        kind = "nss" if "nss" in command else "track"
        out = tmp_path / f"r{i}"
        command = command.replace("PATH/TO/NSS-HDD-Benchmark", str(SHARED / "data" / "nss-hdd-benchmark"))  # the user's copy
        assert run_doc_command(f"{command} --quiet --out {out}") == 0
        pes = json.loads((out / "summary.json").read_text())["runs"]["uncompensated"]["pes_tracks"]
        for key, text in zip(("sigma3", "rro_pp", "nrro_3sigma"), rows[kind]):
            assert _close(pes[key] * 100, text), (kind, key, pes[key] * 100, text)


@pytest.mark.slow  # the README's tour: a run, an identification, a diagnosis of EMPS, a loop, a fleet
def test_the_readme_tour_runs_as_written(tmp_path, monkeypatch, capsys):
    """Every command of the README's five-minute tour, in order, in a fresh folder beside
    ``shared/`` (the HIL row needs a second process and is docs/hil.md's).  Each exits 0
    and writes its page.  (Before: the compensate row was refused, the EMPS model being in
    N against the default 1 A current limit.)"""
    import re
    import shlex

    readme = (ROOT / "README.md").read_text()
    tour = readme[readme.index("## A five-minute tour"):readme.index("## Headline figures")]
    commands = [c for c in re.findall(r"^\| [a-z, ]+ \| `(servo [^`]+)`", tour, re.M) if "--port" not in c]
    assert [shlex.split(c)[1] for c in commands] == ["run", "identify", "diagnose", "compensate", "loop", "fleet"]
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    monkeypatch.chdir(work)
    for command in commands:
        assert run_doc_command(command + " --quiet") == 0, (command, capsys.readouterr().err)
    assert (work / "emps-comp" / "compensator.toml").is_file() and (work / "emps" / "report.html").is_file()


def _recipes() -> list[tuple[str, str]]:
    """Every command line of docs/ and the README's tour that is a recipe (not a synopsis
    with ``[options]``, nor a line of a command's output)."""
    import re

    pages = sorted((ROOT / "docs").glob("*.md"))
    out = [(p.name, c.rstrip("&").strip()) for p in pages for c in doc_commands(p)]
    readme = (ROOT / "README.md").read_text()
    out += [("README.md", c) for c in re.findall(r"^\| [a-z, ]+ \| `(servo [^`]+)`", readme, re.M)]
    return [(page, c) for page, c in out if "[" not in c and not re.match(r"servo [\w-]+:", c)]


#: The recipes no test here runs as written, each with the reason and the test that runs the
#: same command otherwise; every other recipe of docs/ and the README runs in a test above.
ONLY_PARSED = {
    "servo recover OUT.incomplete/log_compensated.journal":
        "needs the journal of a run killed hard; tests/test_hostile.py::test_journals_are_finalised_or_one_error "
        "runs `servo recover` on journals, tests/test_hil.py kills the link under a run",
    "servo diagnose rec.npz --out diag": "rec.npz is the reader's own recording (docs/compensate.md's synopsis "
                                         "of the chain); the chain runs on EMPS and a synthetic drive above",
    "servo compensate diag/report.json --out comp": "the chain on the reader's recording (as above)",
    "servo compensate diag/report.json --paper --out paper": "the chain on the reader's recording (as above)",
    "servo compensate diag/report.json --config base.toml --full --out run": "the reader's base.toml (as above)",
    "servo run --config run/compensator.toml": "the chain on the reader's recording (as above)",
    "servo demo cancel --out cancel": "2.5-6 min on 2 cores; tests/test_cancel_chain.py runs it with --quick",
    "servo paper --out paper-out": "minutes under load; tests/test_paper.py runs the same job on a 3-frequency sweep",
    "servo run --config myrig.toml --port /dev/pts/N --out run1":
        "the reader's rig; tests/test_firmware.py runs `servo run --port` against the firmware (host build and "
        "Cortex-M7 under QEMU)",
}  # fmt: skip


def test_the_recipes_only_parsed_are_few_and_still_on_their_pages():
    """The exceptions above name recipes that exist (a recipe edited out of its page leaves
    the list), and stay few."""
    recipes = {c for _, c in _recipes()}
    assert set(ONLY_PARSED) <= recipes, set(ONLY_PARSED) - recipes
    assert len(ONLY_PARSED) <= 9 and len(ONLY_PARSED) < len(recipes) / 4


def test_every_documented_command_line_is_one_the_cli_accepts():
    """Each recipe of docs/ and the README parses with the CLI's own parser: a renamed or
    removed option, a subcommand that moved, a bad value type fail here (the recipes a
    test runs to the end are the ones above; this covers the other pages' too)."""
    import shlex

    from servo.cli import build_parser

    recipes = _recipes()
    assert len(recipes) >= 35, recipes
    parser = build_parser()
    bad = []
    for page, command in recipes:
        try:
            parser.parse_args(shlex.split(command)[1:])
        except (SystemExit, Exception) as exc:  # noqa: BLE001  (argparse exits; the CLI's own parser raises)
            bad.append(f"{page}: {command}: {exc}")
    assert not bad, "\n".join(bad)


# ------------------------------------------------------------------ the other pages' recipes, run
#
# Each page's commands run once, in order, in one folder beside ``shared/`` (as the pages
# assume: ``../shared/data/...``), and every check of the page reads that folder.  The
# figures are read from the page at test time, so that a page edited with new figures keeps
# its test meaningful.


def _run_captured(command: str) -> tuple[int, str]:
    """Run a documented command in this process; its exit code and everything it printed."""
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = run_doc_command(command)
    return code, out.getvalue()


class _Folder:
    """A working folder beside ``shared/``: each command runs once (the first check that
    needs it), its exit code and printed text kept for the page's other checks."""

    def __init__(self, root: Path):
        self.root = root
        self.done: dict[str, tuple[int, str]] = {}

    def run(self, command: str) -> tuple[int, str]:
        import contextlib

        if command not in self.done:
            with contextlib.chdir(self.root):
                self.done[command] = _run_captured(command)
        return self.done[command]

    def out(self, command: str) -> Path:
        """The folder ``--out`` names in ``command``."""
        import shlex

        argv = shlex.split(command)
        return self.root / argv[argv.index("--out") + 1]


@pytest.fixture(scope="module")
def beside_shared(tmp_path_factory) -> _Folder:
    base = tmp_path_factory.mktemp("recipes")
    (base / "shared").symlink_to(ROOT.parent / "shared")
    (base / "work").mkdir()
    return _Folder(base / "work")


def _page(name: str) -> str:
    return (ROOT / "docs" / name).read_text()


def _between(page: str, start: str, end: str = "\n\n") -> str:
    """The text from ``start`` to ``end`` (a paragraph), its line breaks and runs of spaces
    made one space."""
    i = page.index(start)
    return " ".join(page[i : page.index(end, i + len(start))].split())


PM = r"([-+0-9.]+) \+- ([0-9.]+)"  # "20.39 +- 0.54"


@pytest.mark.slow
def test_diagnosis_page_emps_findings_are_what_diagnose_reports(beside_shared):
    """docs/diagnosis.md, section 11 (EMPS): both commands; the paper's baseline (every
    parameter and its uncertainty, the held-out errors), each finding's table row (name in
    order, parameters +- uncertainty, force error and NRMSE before -> after), and the reduced
    baseline's first findings and end point, each to the digits written."""
    page = _page("diagnosis.md")
    commands = [c for c in doc_commands("docs/diagnosis.md") if "DATA_EMPS" in c]
    assert len(commands) == 2
    for c in commands:
        code, text = beside_shared.run(c)
        assert code == 0, text
    full, reduced = (json.loads((beside_shared.out(c) / "report.json").read_text()) for c in commands)

    para = _between(page, "**Paper's baseline")
    force, nrmse = re.search(r"held-out force error ([0-9.]+) %, output NRMSE ([0-9.]+)", para).groups()
    base = full["baseline"]
    assert _close(base["error"]["test_force_rel_pct"], force) and _close(base["error"]["test_output_nrmse"], nrmse)
    fitted = {k: (t["params"][k], t["std"][k]) for t in base["terms"] for k in t["params"]}
    stated = re.findall(r"`(\w+)` =? ?" + PM, para)
    assert [s[0] for s in stated] == list(fitted), stated
    for term, value, std in stated:
        assert _close(fitted[term][0], value) and _close(fitted[term][1], std), (term, fitted[term], value, std)

    rows = _loop_table(page, "| finding | parameters")
    assert [r[0].strip("`") for r in rows] == [f["physics"] for f in full["findings"]]
    for cells, f in zip(rows, full["findings"]):
        (f0, f1), (n0, n1) = (re.match(r"([0-9.]+) %? ?-> ([0-9.]+)", c).groups() for c in (cells[2], cells[3]))
        got = (f["error_before"]["force_rel_pct"], f["error_after"]["force_rel_pct"],
               f["error_before"]["output_nrmse"], f["error_after"]["output_nrmse"])  # fmt: skip
        assert all(_close(g, t) for g, t in zip(got, (f0, f1, n0, n1))), (f["physics"], got, cells)
        stated = [(k, v, s, 1.0) for k, v, s in re.findall(r"`(\w+)` = " + PM, cells[1])]
        stated += [("dahl_length", v, s, 1e3) for v, s in re.findall(r"Dahl length " + PM + " mm", cells[1])]
        m = re.match(PM + r" N, period ([0-9.]+) mm", cells[1])  # the cogging row: amplitude, period
        if m:
            stated += [("amplitude", m.group(1), m.group(2), 1.0)]
            assert _close(f["params"]["period"] * 1e3, m.group(3)), f
        assert stated, cells
        for key, value, std, scale in stated:
            assert _close(f["params"][key] * scale, value) and _close(f["std"][key] * scale, std), (key, f, cells)

    para = _between(page, "**Reduced baseline")
    force, nrmse = re.search(r"held-out force error ([0-9.]+) %, output NRMSE ([0-9.]+)", para).groups()
    assert _close(reduced["baseline"]["error"]["test_force_rel_pct"], force)
    assert _close(reduced["baseline"]["error"]["test_output_nrmse"], nrmse)
    first = re.findall(r"`(\w+)` \(`(\w+)` = " + PM + r" N[^;]*; ([0-9.]+) % -> ([0-9.]+) %\)", para)
    assert len(first) == 2, para
    for (physics, key, value, std, before, after), f in zip(first, reduced["findings"]):
        assert f["physics"] == physics and _close(f["params"][key], value) and _close(f["std"][key], std), (f, physics)
        assert _close(f["error_before"]["force_rel_pct"], before) and _close(f["error_after"]["force_rel_pct"], after)
    # "then the same three as from the paper's baseline, ending at the same model (2.49 %, NRMSE 0.023)"
    assert [f["physics"] for f in reduced["findings"][2:]] == [f["physics"] for f in full["findings"]]
    end_force, end_nrmse = re.search(r"ending at the same model \(([0-9.]+) %, NRMSE ([0-9.]+)\)", para).groups()
    for report in (full, reduced):
        assert _close(report["final_model"]["error"]["test_force_rel_pct"], end_force), report["final_model"]["error"]
    assert _close(reduced["final_model"]["error"]["test_output_nrmse"], end_nrmse)


@pytest.mark.slow
def test_compensate_page_emps_residuals_are_what_compensate_prints(beside_shared):
    """docs/compensate.md, EMPS: the diagnosis (the same command as docs/diagnosis.md's,
    run once), then `servo compensate ... --recording`: every row of the held-out residual
    table, the rows it is measured on, and the offset it cancels, to the digits written."""
    page = _page("compensate.md")
    diagnose, compensate = [c for c in doc_commands("docs/compensate.md") if "emps" in c]
    assert diagnose.startswith("servo diagnose") and "--recording" in compensate
    for c in (diagnose, compensate):
        code, text = beside_shared.run(c)
        assert code == 0, text
    s = json.loads((beside_shared.out(compensate) / "summary.json").read_text())
    section = page[page.index(compensate.split(" \\")[0][:40]):]
    rows = _loop_table(section, "| compensator | residual |")
    residual = {k: v for k, v in s["residual_pct"].items() if k != "rows"}
    assert len(rows) == len(residual), (rows, residual)
    for cells, (key, value) in zip(rows, residual.items()):
        assert ("without" in cells[0]) == ("without" in key) and cells[0].split()[0] in ("none", "the", "augmented")
        assert _close(value, re.match(r"\**([0-9.]+) %", cells[1]).group(1)), (cells, key, value)
    assert s["residual_pct"]["rows"] == int(re.search(r"\((\d+) rows of the fourth period", section).group(1))
    h0, std, t = re.search(r"`h0` = " + PM + r" N, ([0-9.]+) standard deviations", section).groups()
    assert s["left_out"] == []  # "The offset is cancelled"
    report = json.loads((beside_shared.out(diagnose) / "report.json").read_text())
    (off,) = [term for term in report["final_model"]["terms"] if term["physics"] == "offset"]
    assert _close(off["params"]["h0"], h0) and _close(off["std"]["h0"], std)
    assert _close(abs(off["params"]["h0"]) / off["std"]["h0"], t)
    (eq9,) = [c for c in s["cancelled"] if "eq. 9" in c["name"]]
    assert _close(eq9["keys"]["h0"], h0)


@pytest.mark.slow
def test_identification_page_emps_table_is_what_identify_measures(beside_shared):
    """docs/identification.md, "EMPS": the command as written (its default output folder);
    the measured column, the difference to the published column, the relative error and
    the condition number, to the digits written."""
    page = _page("identification.md")
    (command,) = [c for c in doc_commands("docs/identification.md") if "DATA_EMPS" in c]
    code, text = beside_shared.run(command)
    assert code == 0, text
    summaries = [json.loads(p.read_text()) for p in (beside_shared.root / "servo-out").glob("*/summary.json")]
    (fit,) = [s["fits"]["robust"] for s in summaries if s.get("provenance", {}).get("command", [None, None])[1] == "identify"]
    names = {"M": "J", "Fv": "B", "Fc": "Fc", "offset": "h0"}
    rows = _loop_table(page[page.index(command.split(" --")[0]):], "| | published | measured | difference |")
    assert [r[0].split(" (")[0] for r in rows][:4] == list(names)
    for cells in rows[:4]:
        got = fit["params"][names[cells[0].split(" (")[0]]]
        assert _close(got, cells[2]), (cells, got)
        diff = 100 * (got / float(cells[1]) - 1)
        assert _close(diff, cells[3].rstrip(" %")), (cells, diff)
    rel = next(r for r in rows if r[0] == "relative error")
    cond = next(r for r in rows if r[0] == "condition number")
    assert _close(fit["rel_error_pct"], rel[2].rstrip(" %")) and _close(fit["cond"], cond[2])


def _printed_lines(page: str, after: str) -> list[str]:
    """The indented lines of the code block that follows ``after`` on ``page``: a
    command's output as the page shows it."""
    lines = page[page.index(after) + len(after):].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("    "))
    out = []
    for line in lines[start:]:
        if not line.startswith("    "):
            break
        out.append(line.strip())
    return out


def _shows(text: str, line: str) -> bool:
    """``line`` (a page's rendering of an output line, ``...`` for what it elides) is one
    of ``text``'s lines, spaces collapsed."""
    pattern = ".*".join(re.escape(" ".join(p.split())) for p in line.split("..."))
    return any(re.search(pattern, " ".join(t.split())) for t in text.splitlines())


@pytest.mark.slow
def test_compensate_page_synthetic_round_trip_prints_the_page(beside_shared):
    """docs/compensate.md, the synthetic round trip: the three commands, the last refused
    (exit 2) with every line the page shows, figures included."""
    page = _page("compensate.md")
    commands = [c for c in doc_commands("docs/compensate.md") if "syn" in c or "diag/final_model" in c]
    assert [c.split()[1] for c in commands] == ["fleet", "diagnose", "compensate"], commands
    codes, texts = zip(*(beside_shared.run(c) for c in commands))
    assert codes == (0, 0, 2), texts[-1]
    shown = _printed_lines(page, "Now:")
    assert len(shown) >= 6 and shown[-1].startswith("servo: error:")
    missing = [line for line in shown if not _shows(texts[-1], line)]
    assert not missing, (missing, texts[-1])


@pytest.mark.slow
def test_loop_page_first_command_measures_the_tables_small_signal_rows(tmp_path):
    """docs/loop.md's first command (its output folder moved to the test's): the designs'
    rows and the 0.2 mA rows of the "Measured" table."""
    page = _page("loop.md")
    command = doc_commands("docs/loop.md")[0]
    assert command.startswith("servo loop --out ")
    out = tmp_path / "loop"
    assert run_doc_command(command.replace(command.split()[-1], str(out)) + " --quiet") == 0
    summary = json.loads((out / "summary.json").read_text())
    measured = {e["label"] for e in summary["runs"]}
    rows = [r for r in _loop_table(page, "## Measured (default drive") if r[0] in DESIGN_ROWS or r[0] in measured]
    assert sum(r[0] in measured for r in rows) == 2 and len(rows) == 5, rows
    _check_loop_rows(summary, rows)


@pytest.mark.slow
def test_hdd_page_loop_recipe_gives_its_margins(tmp_path):
    """docs/hdd.md: `servo loop --config examples/hdd-nss-v2.toml ...` measures the
    crossover, phase margin, gain margin (side, frequency) and max|S| the page states, and
    the design's, to the digits written."""
    page = _page("hdd.md")
    (command,) = [c for c in doc_commands("docs/hdd.md") if c.startswith("servo loop --config examples/hdd-")]
    assert run_doc_command(f"{command} --quiet --out {tmp_path / 'loop'}") == 0
    summary = json.loads((tmp_path / "loop" / "summary.json").read_text())
    text = " ".join(page[page.index(command.split(" --f-min")[0]):].split())
    m = re.search(r"gives crossover ([0-9.]+) Hz, phase margin ([0-9.]+) deg, gain margin ([-+0-9.]+) dB \((upper|lower), "
                  r"([0-9.]+) Hz\), max\|S\| ([0-9.]+) dB, against the design's ([0-9.]+) Hz, ([0-9.]+) deg, ([-+0-9.]+) dB, "
                  r"([0-9.]+) dB", text)  # fmt: skip
    fc, pm, gm, side, f180, s_max, d_fc, d_pm, d_gm, d_s = m.groups()
    got = summary["runs"][0]["margins"]
    assert _close(got["crossover_hz"], fc) and _close(got["phase_margin_deg"], pm), got
    assert _close(got["gain_margin_db"], gm) and got["gain_margin_side"] == side and _close(got["gain_margin_hz"], f180)
    assert _close(got["max_S_db"], s_max), got
    design = summary["designs"]["drive model, pivot small-signal, no comp."]
    for key, text_value in (("crossover_hz", d_fc), ("phase_margin_deg", d_pm), ("gain_margin_db", d_gm), ("max_S_db", d_s)):
        assert _close(design[key], text_value), (key, design[key], text_value)


@pytest.mark.slow
def test_realtime_page_warmup_line():
    """docs/realtime.md: `servo warmup` prints the line the page shows, with as many
    kernels (compiled plus loaded from the cache) as the page counts."""
    (command,) = [c for c in doc_commands("docs/realtime.md") if c.startswith("servo warmup")]
    line = next(x for x in _page("realtime.md").splitlines() if x.strip().startswith(command))
    stated = int(re.search(r"# servo warmup: (\d+) kernels compiled", line).group(1))
    import subprocess
    import sys

    # a fresh process, as a user runs it (this one has loaded the kernels already)
    done = subprocess.run([sys.executable, "-m", "servo", *command.split()[1:]], capture_output=True, text=True)
    text = done.stdout + done.stderr
    assert done.returncode == 0, text
    compiled, loaded = map(int, re.search(r"servo warmup: (\d+) kernels compiled, (\d+) loaded from the cache, "
                                          r"[0-9.]+ s; cached in \S+", text).groups())  # fmt: skip
    assert compiled + loaded == stated, text


@pytest.mark.slow
def test_runtime_page_unstable_plugin_stops_with_the_pages_line(tmp_path, monkeypatch):
    """docs/runtime.md, "Instability": the plug-in PID with `kd = 0` (the module of
    tests/test_instability.py, which the page describes) stops with exit 3 and the error
    line the page shows."""
    from servo.controllers import KINDS
    from tests.test_instability import PID

    page = _page("runtime.md")
    (command,) = [c for c in doc_commands("docs/runtime.md") if "--plugin my_pid" in c]
    (tmp_path / "my_pid.py").write_text(PID)
    monkeypatch.chdir(tmp_path)
    before = dict(KINDS)
    try:
        code, text = _run_captured(command)
    finally:
        KINDS.clear()
        KINDS.update(before)
    (shown,) = _printed_lines(page, command)
    assert code == 3 and _shows(text, shown), (code, text, shown)


def _emulate_args(command: str) -> list[str]:
    import shlex

    argv = shlex.split(command.rstrip("&").strip())
    assert argv[:2] == ["servo", "emulate"], command
    return argv[2:]


@pytest.mark.slow
def test_hil_page_run_through_the_emulator_is_the_simulated_run(tmp_path):
    """docs/hil.md: `servo emulate` as written, then `servo run --port /dev/pts/N` with the
    pty it printed: the run through the link (lockstep) records, bit for bit, what the
    same job records on the simulated drive (the README's `servo run`)."""
    import servo
    from tests.test_hil import emulator

    emulate, run = doc_commands("docs/hil.md")[:2]
    assert run.startswith("servo run --port /dev/pts/N")
    sim = "servo run"  # the README tour's first command, its folder given
    with emulator(*_emulate_args(emulate)) as (_, url):
        assert run_doc_command(run.replace("/dev/pts/N", url) + f" --quiet --out {tmp_path / 'hil'}") == 0
    assert run_doc_command(f"{sim} --quiet --out {tmp_path / 'sim'}") == 0
    hil, ref = servo.load_run(tmp_path / "hil"), servo.load_run(tmp_path / "sim")
    assert set(hil.labels) == set(ref.labels) == {"compensated", "uncompensated"}
    for label in ref.labels:
        for col in ("x", "u", "e"):
            assert np.array_equal(hil.logs[label][col], ref.logs[label][col]), (label, col)


@pytest.mark.slow
def test_loop_page_measurement_through_the_emulator_is_the_tables(tmp_path):
    """docs/loop.md: `servo emulate --pty --set scenario.disturbance_amplitude=0 &`, then
    `servo loop --port /dev/pts/N --compensator on` ("the same through the link"): the
    "Measured" table's compensated 0.2 mA row, to the digits written."""
    from tests.test_hil import emulator

    page = _page("loop.md")
    emulate, loop = [c for c in doc_commands("docs/loop.md") if c.startswith("servo emulate") or "--port" in c]
    with emulator(*_emulate_args(emulate)) as (_, url):
        assert run_doc_command(loop.replace("/dev/pts/N", url) + f" --quiet --out {tmp_path / 'loop'}") == 0
    summary = json.loads((tmp_path / "loop" / "summary.json").read_text())
    (label,) = [e["label"] for e in summary["runs"]]
    rows = [r for r in _loop_table(page, "## Measured (default drive") if r[0] == label]
    assert len(rows) == 1, (label, rows)
    _check_loop_rows(summary, rows)


@pytest.mark.slow
def test_fleet_page_scheduler_recipe_runs_on_a_scheduler_of_its_own(tmp_path, monkeypatch):
    """docs/fleet.md, `--scheduler`: the page's `dask scheduler` and two `dask worker`
    lines, then its `servo fleet diagnose 'lab/*.npz' --scheduler ...` on a two-drive
    synthetic lab.  Two changes, both of the machine, not of the recipe: a free port instead
    of 8786 and no scheduler dashboard (other users of the machine may hold 8786/8787)."""
    import shlex
    import socket
    import subprocess
    import sys

    from distributed import Client

    page = _page("fleet.md")
    block = page[page.index("      dask scheduler"):].split("\n\n")[0].splitlines()
    dask_lines = [shlex.split(line.strip().rstrip("&")) for line in block if line.strip().startswith("dask ")]
    (command,) = [c for c in doc_commands("docs/fleet.md") if "--scheduler" in c]
    assert [a[:2] for a in dask_lines] == [["dask", "scheduler"], ["dask", "worker"], ["dask", "worker"]]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    dask = str(Path(sys.executable).parent / "dask")
    procs = []
    monkeypatch.chdir(tmp_path)
    try:
        for argv in dask_lines:
            argv = [dask, *(a.replace("8786", str(port)) for a in argv[1:])] + (["--no-dashboard"] if argv[1] == "scheduler" else [])
            procs.append(subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        address = f"tcp://127.0.0.1:{port}"
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
        assert run_doc_command("servo fleet synthetic --drives 2 --defects 0 --quiet --out lab") == 0
        code, text = _run_captured(command.replace("tcp://127.0.0.1:8786", address))
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    assert code == 0, text
    (fleet,) = (tmp_path / "servo-out").glob("*/fleet.json")
    summary = json.loads(fleet.read_text())
    assert summary["ok"] == 2 and summary["failed"] == 0, summary
    assert address in text or address in json.dumps(summary), text  # it ran on that cluster, and says so

"""The commands the docs pages show, run as written (parsed from the page, so page and
test cannot drift apart), each checked against what its page states, over the whole
stated range."""
from __future__ import annotations

import json
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

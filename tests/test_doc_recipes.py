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
from tests.helpers import doc_commands, run_doc_command

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

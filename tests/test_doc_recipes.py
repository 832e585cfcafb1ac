"""The commands the docs pages show, run as written (parsed from the page, so page and
test cannot drift apart), each checked against what its page states, over the whole
stated range."""
from __future__ import annotations

import json

import numpy as np
import pytest

from servo.config import Config
from servo.io.frequency_response import load_frequency_responses
from tests.helpers import doc_commands, run_doc_command


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

"""A hysteretic benchmark sampled slowly for its motion (issue 24): a Bouc-Wen element at
750 Hz driven by a force multisine of 5-150 Hz, a reversal every few samples, as the
third-party Bouc-Wen benchmark is.  It was refused ("too few usable rows"); it gets a
verdict now, ``out_of_scope`` with the cause measured, in a report (docs/verdict.md)."""
import json

import numpy as np
import pytest

from servo.cli import main
from servo.io.recording import save_recording_csv
from studies.proving.cases import Case, recording

#: the benchmark's rate and band: f_m = 50 Hz puts the force multisine's tones at 5-150 Hz
RATE_HZ, MOTION_HZ = 750.0, 50.0


def _bouc_wen(size: float):
    return recording(Case("bouc_wen", size, "force", "multisine", RATE_HZ, 30000, motion_hz=MOTION_HZ), 1)[0]


def test_a_fast_motion_case_reverses_every_few_samples():
    """The recipe makes what the benchmark is: the measured position reverses every few
    samples (the Case's ``motion_hz`` takes the motion off its default ``fs/2000``)."""
    for size in (0.0, 1.0):
        x = _bouc_wen(size).x
        dx = np.diff(x)
        dx = dx[np.abs(dx) > 1e-12]
        reversals = np.count_nonzero(np.sign(dx[1:]) != np.sign(dx[:-1]))
        assert x.size / reversals < 5, size


@pytest.mark.slow
@pytest.mark.parametrize("size", [0.0, 0.3, 1.0])
def test_bouc_wen_at_750_hz_gets_out_of_scope_with_its_cause_in_a_report(tmp_path, capsys, size):
    """Not a refusal: exit 0, ``report.json`` and ``report.html``, the verdict
    ``out_of_scope`` whose reason is one of the two the band chooser measures (the speed
    within its noise, or reversals closer than the decimation filter's reach) with its
    numbers."""
    rec = _bouc_wen(size)
    path = tmp_path / "bw.csv"
    save_recording_csv(path, rec)
    out = tmp_path / "o"
    assert main(["diagnose", str(path), "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    r = json.loads((out / "report.json").read_text())
    assert r["verdict"] == "out_of_scope" and r["findings"] == [], r["verdict_text"]
    text = r["verdict_text"]
    assert text.startswith("too few usable rows: "), text
    assert ("reverses" in text and "samples (median)" in text) or ("within its noise" in text and "% of" in text), text
    assert (out / "report.html").is_file()

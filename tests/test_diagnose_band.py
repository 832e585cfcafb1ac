"""The rows' band chosen from the recording: a decimation the reversals allow, the band
stated, and an out-of-scope verdict that names its cause (issue 11.3, issue 24.6)."""
import re

import numpy as np
import pytest

from servo.diagnose.band import band_hz, choose
from servo.diagnose.job import Options, diagnose, prepare
from servo.diagnose.scope import OutOfDomain
import studies.proving.integrate as ig
from servo.identify.regressors import IdentificationError, RobustSettings
from servo.io.recording import Recording

FS = 750.0


def _recording(f_hz: float, amplitude: float = 3.0, n: int = 20000) -> Recording:
    """An arm (J = 2, B = 5, Coulomb 0.5, K = 10) driven open loop at 750 Hz by two
    sines of ``f_hz`` and 2.7*``f_hz`` plus a little noise (the independent integrator)."""
    p = np.zeros(ig.N_PARAMS)
    p[ig.P_RATE], p[ig.P_J], p[ig.P_NSUB], p[ig.P_COG_PERIOD] = FS, 2.0, 4, 1.0
    p[ig.P_B], p[ig.P_FC], p[ig.P_FS], p[ig.P_VS] = 5.0, 0.5, 0.5, 1e-3
    p[ig.P_NOISE], p[ig.P_K], p[ig.P_H0] = 1e-7, 10.0, 0.1
    t = np.arange(n) / FS
    rng = np.random.default_rng(1)
    w = amplitude * (np.sin(2 * np.pi * f_hz * t) + np.sin(2 * np.pi * 2.7 * f_hz * t + 1) / 3) + 0.3 * rng.standard_normal(n)
    u, y, x = np.zeros(n), np.zeros(n), np.zeros(n)
    ig.run(p, np.zeros(n), w, np.full(n, 1e30), np.ones(n), rng.standard_normal(n), np.zeros(1), np.ones(1),
           np.zeros(0), np.zeros(0), u, y, x, n)  # fmt: skip
    return Recording(t, u, y, None, source=f"750 Hz, {f_hz:g} Hz drive")


@pytest.mark.slow
def test_reversals_close_in_samples_get_a_smaller_decimation_and_the_band_is_stated():
    rec = _recording(10.0)  # a reversal every ~37 samples: a third of them inside the default filter's reach
    fixed = diagnose(rec, Options(settings=RobustSettings()))
    chosen = diagnose(rec, Options(band="reversals"))  # the reversals alone (the power rule: test_diagnose_power_band)
    q = chosen.sig.settings.decimate
    # (the default keeps 28 % of the rows since rows whose friction sign the filter cannot
    # tell are left out, signals.py; 30 % before)
    assert q < 10 and chosen.sig.valid.mean() > fixed.sig.valid.mean() >= 0.25
    assert chosen.sig.valid.mean() >= 0.6
    assert f"decimation by {q}" in chosen.band_note and "usable" in chosen.band_note
    assert band_hz(chosen.sig.settings, FS) == pytest.approx(0.4 * FS / q)
    assert chosen.final_fit.combined()["inertia"]["J"] == pytest.approx(2.0, rel=0.01)
    # a slow motion keeps the default
    slow = diagnose(_recording(2.5), Options(band="reversals"))
    assert slow.sig.settings.decimate == 10
    assert slow.band_note.startswith("decimation by 10: the motion reverses every 151 samples (median), 81 % of the rows")  # 89 % before the uncertain rows left


def test_out_of_scope_names_its_cause():
    """No decimation leaves rows to fit: the verdict ``out_of_scope`` says what was
    measured (not a refusal: the data were read)."""
    D = diagnose(_recording(40.0), Options())  # a reversal every ~9 samples: no decimation helps
    assert D.verdict["verdict"] == "out_of_scope" and not D.findings
    assert re.search(r"reverses \d+ times, every \d+ samples", D.verdict["text"]), D.verdict["text"]
    rng = np.random.default_rng(2)
    t = np.arange(20000) / FS
    at_rest = Recording(t, rng.standard_normal(t.size), 1e-9 * rng.standard_normal(t.size), None, source="at rest")
    D = diagnose(at_rest, Options())
    assert D.verdict["verdict"] == "out_of_scope" and "barely moves" in D.verdict["text"]
    # the band's choice raises it as an error of the identification (a library caller
    # that refuses still refuses in one line), which the diagnosis turns into the verdict
    with pytest.raises(OutOfDomain, match="barely moves") as info:
        choose(at_rest, Options(), prepare)
    assert isinstance(info.value, IdentificationError)

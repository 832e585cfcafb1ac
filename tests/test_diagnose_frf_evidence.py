"""Frequency evidence joined with the verdict (issue 24, item 1): the recording's own
input-to-position response over the whole band with excitation, against the model's.

Recordings of the independent generator (studies/proving/): the two cases of the issue
(a mode above the rows' band under PRBS; two modes, the second at about 3 kHz) with
their expected verdicts, nulls that must stay ``consistent``, and a mode the rows would
name where the response does not show it."""
import math

import numpy as np
import pytest
from scipy import signal

from servo.diagnose import frf_modes as fm
from servo.diagnose.fit import fit_model
from servo.diagnose.job import diagnose
from servo.diagnose.model import Term
from studies.proving.cases import Case, recording


def _prbs_lti(modes, fs=20000.0, n=40000, noise=1e-9, seed=1):
    """Open loop, exactly simulated (zero-order hold): a rigid body on a soft spring
    (``1/(J s^2 + B s + K)``) plus ``modes`` ``[(hz, zeta, gain)]`` in the measured
    position, driven by a slow stroke plus a PRBS (clock 3 samples), sensor white noise
    ``noise`` (m).  The PRBS drives the arm above the rows' Butterworth far more than
    the noise does: the rows' ``sigma_x`` reads about 100 x the true noise here (issue
    24, item 2: 27 x on the recording of its first case)."""
    from servo.io.recording import Recording

    J, B, K = 1e-3, 1e-3 * 2 * math.pi * 5, 1e-3 * (2 * math.pi * 5) ** 2
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    u = 0.05 * np.repeat(rng.choice([-1.0, 1.0], n // 3 + 1), 3)[:n] + 0.3 * np.sin(2 * np.pi * 3.0 * t)
    bd, ad, _ = signal.cont2discrete(([1.0], [J, B, K]), 1 / fs, method="zoh")
    x = signal.lfilter(np.ravel(bd), ad, u)
    for hz, z, g in modes:
        w = 2 * math.pi * hz
        bd, ad, _ = signal.cont2discrete(([g / J], [1.0, 2 * z * w, w * w]), 1 / fs, method="zoh")
        x = x + signal.lfilter(np.ravel(bd), ad, u)
    return Recording(t, u, x + noise * rng.standard_normal(n), None, source="prbs, exact")


def test_one_mode_far_above_the_rows_band_is_named_and_the_floor_is_not_inflated():
    """Issue 24's first case, its mechanism reproduced exactly: one 3 kHz mode (a 50 %
    peak) under a PRBS at 20 kHz, the rows' band ending at 800 Hz.  Before, the floor
    was what the rows' Butterworth removes, about 100 x the 1 nm truth, and the bins
    were kept only where the model predicted 3 x that inflated noise, none near 3 kHz:
    ``consistent``.  Now the floor is read where the input drives nothing
    (:mod:`servo.diagnose.noise`) and the mode is named from the response
    (``explained``)."""
    D = diagnose(_prbs_lti([(3000.0, 0.01, 0.01)]))
    assert 0.5e-9 < D.sig.noise_x < 2e-9  # the 1 nm sensor noise, within the factor 2
    assert D.verdict["baseline_checks"]["frf"]["failed"]
    assert D.verdict["verdict"] == "explained", D.verdict["text"]
    (m,) = [f for f in D.findings if f.physics == "resonance"]
    assert m.frf is not None and m.params["frequency_hz"] == pytest.approx(3000.0, rel=0.005)
    assert m.params["gain"] == pytest.approx(0.01, rel=0.1)


def test_two_modes_the_second_at_3_khz_are_both_named_and_explained():
    """Issue 24's second case, its mechanism reproduced exactly: modes at 1.2 and 3 kHz.
    Before, the 1.2 kHz one was named and the 3 kHz departure left the verdict
    ``unexplained``; now both are fitted from the response to 0.5 %, each departure
    located, and the final model's response agrees with the recording's."""
    D = diagnose(_prbs_lti([(1200.0, 0.01, 0.02), (3000.0, 0.01, 0.02)]))
    modes = _named_modes(D)
    assert len(modes) == 2 and modes == [pytest.approx(1200.0, rel=0.005), pytest.approx(3000.0, rel=0.005)]
    deps = D.verdict["baseline_checks"]["frf"]["departures"]
    peaks = [d["peak_hz"] for d in deps]  # each departure located, at a mode (a mode's flanks may split in two)
    assert {round(p / 100) for p in peaks} >= {12, 30}
    assert all(min(abs(p / 1200 - 1), abs(p / 3000 - 1)) < 0.15 for p in peaks), peaks
    assert not D.verdict["final_checks"]["frf"]["failed"]
    assert D.verdict["verdict"] == "explained", D.verdict["text"]


def _named_modes(D):
    return sorted(f.params["frequency_hz"] for f in D.findings if f.physics == "resonance")


def test_a_mode_above_the_rows_band_under_prbs_is_not_consistent():
    """Issue 24's first case: one lightly damped mode above the rows' band, PRBS, closed
    loop (the generator's ``mode_above_band``: 0.07 fs, above the rows' edge of 0.04 fs
    at decimation by 10).  The rows cannot see it; the response does: the mode is named
    from it and the verdict is never ``consistent``."""
    rec, truth = recording(Case("mode_above_band", 0.03, "pdi", "prbs", 5000.0), seed=310021)
    D = diagnose(rec)
    assert D.sig.settings.decimate == 10
    assert D.verdict["verdict"] != "consistent", D.verdict["text"]
    assert any(f.frf is not None for f in D.findings)  # named from the response, not the rows
    modes = _named_modes(D)
    assert any(abs(m / (0.07 * 5000.0) - 1) < 0.02 for m in modes), modes


def test_the_modes_family_at_20_khz_has_its_two_modes_in_reach_named():
    """The generator's ``modes`` family at 20 kHz, open loop, PRBS (modes at 0.06 and
    0.15 fs within reach of the PRBS: 1.19 and 2.91 kHz; the ones at 5.4 and 8.6 kHz
    sit where the PRBS, clocked every 3 samples, has little power): both are named,
    the departures located where the coherence is high, never ``consistent``."""
    rec, truth = recording(Case("modes", 0.01, "force", "prbs", 20000.0), seed=7)
    D = diagnose(rec)
    modes = _named_modes(D)
    for hz in truth["modes_hz"][:2]:
        assert any(abs(m / hz - 1) < 0.02 for m in modes), (hz, modes)
    assert D.verdict["verdict"] != "consistent"
    assert D.verdict["baseline_checks"]["frf"]["failed"]
    fr = D.verdict["baseline_checks"]["frf"]
    assert fr["departures"] and all(d["coherence"] >= fm.COH_MIN for d in fr["departures"])
    if D.verdict["final_checks"]["frf"]["failed"]:  # a departure left: never "explained"
        assert D.verdict["verdict"] == "unexplained"


@pytest.mark.parametrize("controller,excitation,noise,seed", [("pdi", "prbs", "white", 300002),
                                                              ("force", "prbs", "pink", 300006)])
def test_a_null_with_broadband_excitation_stays_consistent(controller, excitation, noise, seed):
    """No false departure on a null whose input has power up to the Nyquist frequency:
    the response is compared over 100-500 coherent bins and nothing departs."""
    rec, _ = recording(Case("null", 0.0, controller, excitation, 5000.0, noise=noise), seed=seed)
    D = diagnose(rec)
    fr = D.verdict["final_checks"]["frf"]
    assert fr["ran"] and fr["bins"] >= 100 and not fr["failed"]
    assert D.findings == []
    assert D.verdict["verdict"] == "consistent", D.verdict["text"]


def test_a_mode_the_response_does_not_show_has_no_support():
    """A resonance added to a null's model at a frequency where nothing is: the
    recording's own response does not support it (``support`` says why); the same
    check supports a mode the response does show."""
    rec, _ = recording(Case("null", 0.0, "force", "prbs", 5000.0), seed=300006)
    D = diagnose(rec)
    fit = D.final_fit
    fake = fit_model(D.design, fit.model.plus(Term.make("resonance", {"frequency_hz": 96.0, "zeta": 0.02}, (0.01,))))
    (i, ok, ev), = fm.support(D.design, fake, 0.05)
    assert fake.model.terms[i].physics == "resonance" and not ok
    assert "does not show it" in ev["reason"]
    rec, truth = recording(Case("mode_above_band", 0.01, "force", "prbs", 5000.0), seed=310021)
    D = diagnose(rec)  # open loop, decimation by 3: the rows name the 350 Hz mode, and the response shows it
    assert len(_named_modes(D)) == 1
    assert [ok for _, ok, _ in fm.support(D.design, D.final_fit, 0.05)] == [True]


@pytest.mark.slow
def test_the_frequency_check_false_alarm_level_on_nulls():
    """The ``frf`` check's false alarms on nulls of every cell of the second grid with
    power in the band (closed and open loop, four excitations, white and coloured
    noise, development seeds): none on 16 nulls (its level is ``alpha`` = 0.05
    family-wise per recording, Bonferroni over the bins)."""
    from studies.proving.study import grid_cell

    fails, ran = [], 0
    for j in range(16):
        ctl, exc, noise = grid_cell("null", 0, j)
        rec, _ = recording(Case("null", 0.0, ctl, exc, 5000.0, noise=noise), seed=300_000 + j)
        try:
            D = diagnose(rec)
        except Exception:  # a refusal: not a false departure
            continue
        if D.verdict["verdict"] == "out_of_scope":  # no rows to compare (issue 24, 6): not a false departure
            continue
        ran += D.verdict["final_checks"]["frf"]["ran"]
        if D.verdict["baseline_checks"]["frf"]["failed"] or any(f.physics == "resonance" for f in D.findings):
            fails.append((ctl, exc, noise))
    assert ran >= 8
    assert fails == []

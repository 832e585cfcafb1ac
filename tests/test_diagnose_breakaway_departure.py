"""The breakaway's peak read at the departure from rest, a force held either way, and the
split proof where the held-out part holds too few rests (servo/diagnose/breakaway.py,
docs/diagnosis.md section 4b).

Development recordings of the proving ground (offset 40000 of its study) that main's
test missed with their breakaway changing the held-out error by 27-49 %, and null
recordings of the same controllers and excitations (long holds: seeks, a slow pulse
train), on which nothing may be named.
"""
import numpy as np
import pytest

from servo.diagnose import breakaway
from servo.diagnose.job import diagnose
from studies.proving.cases import Case, recording
from servo.diagnose.report import build_report


class _Sig:
    """The parts of Signals that :func:`breakaway.departures` reads."""

    dt = 1.0

    class settings:
        @staticmethod
        def cutoff(fs):
            return fs / 10.0  # a Butterworth time scale of 10 samples: WIDEN 2 -> 20 samples


def test_departure_window_is_around_the_last_exit_from_rest():
    """A hold of 500 samples with a short stop inside: the window is the 41 samples around
    the last exit from rest; an event without an exit keeps its whole window."""
    rest = np.zeros(2000, bool)
    rest[300:700] = True
    rest[705:800] = True  # a short creep, then held again: the last exit is at 800
    rest[1500:2000] = True  # rests to the end: no departure
    a, b = np.array([280, 1480]), np.array([820, 2000])
    da, db = breakaway.departures(_Sig, a, b, rest)
    assert (da[0], db[0]) == (780, 820)  # 800 - 20 .. the event's end (800 + 21 capped at 820)
    assert (da[1], db[1]) == (1480, 2000)


def test_held_counts_a_force_inside_a_long_enough_rest_only():
    still = np.array([0, 1, 1, 1, 1, 0, 1, 1, 0], bool)
    runs = breakaway.still_runs(still)
    assert [breakaway._held(runs, i, 4) for i in range(9)] == [False, True, True, True, True, False, False, False,
                                                              False]  # fmt: skip
    whole = breakaway.still_runs(np.ones(5, bool))
    assert breakaway._held(whole, 0, 5) and breakaway._held(whole, 4, 5) and not breakaway._held(whole, 2, 6)


@pytest.mark.parametrize("case,seed,proof", [
    # open loop, 500 Hz pulses: holds of 1400-1600 samples among few sliding samples (the
    # union bound gave every one p = 1), the input flipping while the arm is held
    (Case("karnopp", 1.0, "open", "pulses", 500.0), 100002, "held-out part"),
    # lead-lag seeks: the held-out part holds one rest, too few to test a breakaway alone
    (Case("karnopp", 0.5, "leadlag", "seeks", 5000.0), 100011, "training events held out from the fit"),
])  # fmt: skip
def test_breakaway_found_on_long_holds(case, seed, proof):
    rec, truth = recording(case, seed)
    D = diagnose(rec)
    f = next(f for f in D.findings if f.physics == "stribeck_friction")
    ev = f.breakaway
    assert ev["proof"] == proof and ev["p"] < ev["level"] and ev["p_test"] < 0.05
    assert truth["Fc"] < f.params["Fs"] < 1.15 * truth["Fs"]
    if proof != "held-out part":
        assert 0 < ev["events_at_rest_heldout"] < breakaway.MIN_REST_TEST
        assert "cannot test a breakaway on its own" in f.where["text"]
        assert "of its 1 events beyond the bound, p " in f.where["text"]  # what its own rest gave is said


@pytest.mark.parametrize("case,seed", [
    (Case("null", 0.0, "open", "pulses", 500.0), 90002),
    (Case("null", 0.0, "leadlag", "seeks", 5000.0), 90011),
    (Case("null", 0.0, "pdi", "seeks", 1000.0), 90005),
])  # fmt: skip
def test_null_long_holds_name_nothing(case, seed):
    """Without a breakaway the same long holds hold nothing beyond the sliding level: no
    event near its noise's tail, the combined p-values far from any level."""
    rec, _ = recording(case, seed)
    D = diagnose(rec)
    assert not any(f.physics == "stribeck_friction" for f in D.findings)
    res = breakaway.test(D.design, D.final_fit)
    assert res.events is not None and res.events.start.size >= 3
    assert np.count_nonzero(res.events.pvalue <= 0.01) == 0
    assert res.p > 0.05
    report = build_report(D)
    assert "stribeck_friction" not in [x["physics"] for x in report["findings"]]


def test_held_force_and_sliding_sign_through_a_named_sensor_lag():
    """A sensor low-pass (fs/10, open loop, multisine at 1 kHz) named ``sensor_lag``: the
    held force's columns and the sliding level's switch are the force balance's under the
    lag (``Design.full_columns``), so the sliding misfit the events are compared with is
    smaller than with the recorded velocity's sign, and nothing is held at rest."""
    rec, _ = recording(Case("sensor_lowpass", 10.0, "open", "multisine", 1000.0), 100001)
    D = diagnose(rec)
    fit = D.final_fit
    assert fit.model.has("sensor_lag")
    ci = next(i for i, t in enumerate(fit.model.terms) if t.physics == "coulomb_friction")
    Fc = float(fit.combined()["coulomb_friction"]["Fc"])
    f = breakaway.held_force(D.design, fit)
    a, b = breakaway.events(D.sig)
    sliding = np.ones(D.sig.n, bool)
    for s, e in zip(a, b):
        sliding[s:e] = False
    st = D.sig.settings
    sliding[: st.trim_start] = sliding[D.sig.n - st.trim_end :] = False
    rms = [float(np.sqrt(np.mean((f - Fc * sg)[sliding] ** 2))) for sg in (D.sig.sign_v, breakaway.sliding_sign(D.design, fit, ci))]
    assert rms[1] < 0.95 * rms[0]
    res = breakaway.test(D.design, fit)
    assert res.p > 0.05 and not any(x.physics == "stribeck_friction" for x in D.findings)

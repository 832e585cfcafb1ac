"""Modes, delays and sensor lags on the proving ground's open-loop PRBS recordings
(:mod:`studies.proving`, development seeds): a binary input's level is no dead zone, and
a delay shorter than a tenth of a sample is still a delay."""
import numpy as np
import pytest

from servo.diagnose.job import diagnose
from servo.physics.dead_zone import DeadZone
from studies.proving.cases import Case, recording


@pytest.mark.parametrize("kind", ["half_normal", "uniform", "binary", "binary_with_edges", "single"])
def test_the_widest_dead_zone_passes_its_share_of_the_input(kind):
    """``DeadZone.widest`` is the half-width at which ``mean(max(|u| - w, 0))`` is exactly
    ``PASS_MIN`` of ``mean(|u|)``: a binary input's half-width is at most 0.9 of its level."""
    rng = np.random.default_rng(3)
    au = {"half_normal": np.abs(rng.standard_normal(5000)), "uniform": rng.uniform(size=5000),
          "binary": np.full(800, 2e-4), "binary_with_edges": np.r_[np.full(900, 1.0), rng.uniform(0, 1, 100)],
          "single": np.array([3.0])}[kind]  # fmt: skip
    w = DeadZone.widest(au)
    assert 0 < w < au.max()
    assert np.mean(np.maximum(au - w, 0)) == pytest.approx(DeadZone.PASS_MIN * au.mean(), rel=1e-9)
    if kind == "binary":
        assert w == pytest.approx(0.9 * 2e-4)
    assert DeadZone.widest(np.zeros(10)) == 0.0


def _diagnosed(family, size, seed, noise):
    rec, truth = recording(Case(family, size, "force", "prbs", 5000.0, noise=noise), seed)
    return diagnose(rec)


@pytest.mark.parametrize("family,size,seed,noise", [("delay", 0.1, 310001, "white"), ("delay", 0.5, 310203, "pink")])
def test_an_open_loop_prbs_delay_is_named_not_hidden_by_a_dead_zone(family, size, seed, noise):
    """An open-loop PRBS's ``|u|`` is one value: a dead zone of that half-width zeroed the
    input, the force balance was met by J = 0, and the delay was never named (the term was
    then refused as out of scope).  Now the delay is named with its size."""
    D = _diagnosed(family, size, seed, noise)
    assert "dead_zone" not in D.implausible
    f = [f for f in D.findings if f.physics == "time_delay"]
    assert f, [(g.physics, g.params) for g in D.findings]
    assert f[0].params["delay_s"] * 5000.0 == pytest.approx(size, rel=0.15)


def test_a_sensor_lowpass_at_half_the_sample_rate_is_its_mean_delay():
    """A one-pole low-pass at ``fs/2`` (``a = 1 - exp(-pi)``) delays by ``(1 - a)/a`` =
    0.045 samples at low frequency; the rows cannot tell it from a delay (the proving
    ground accepts either name there), and the delay grid now holds twentieths of a sample."""
    D = _diagnosed("sensor_lowpass", 2.0, 310001, "white")
    f = [f for f in D.findings if f.physics in ("time_delay", "sensor_lag")]
    assert f, [(g.physics, g.params) for g in D.findings]
    a = 1 - np.exp(-np.pi)
    if f[0].physics == "time_delay":
        assert f[0].params["delay_s"] * 5000.0 == pytest.approx((1 - a) / a, rel=0.3)


def _swapped(family, size, seed, to):
    """The closed-loop PRBS recording's diagnosis, its input-path term replaced by ``to``
    (the parameter carried over), refitted, and held against the frequency response."""
    from servo.diagnose import frf_modes
    from servo.diagnose.fit import fit_model
    from servo.diagnose.model import Model, Term

    rec, _ = recording(Case(family, size, "pdi", "prbs", 5000.0, noise="white"), seed)
    D = diagnose(rec)
    m = D.final_fit.model
    held = [t for t in m.terms if t.physics in ("time_delay", "sensor_lag")]
    assert len(held) == 1, [(f.physics, f.params) for f in D.findings]
    own = frf_modes.input_path(D.design, D.final_fit, 0.05, rec.r)
    value = next(iter(held[0].params.values()))
    alt = Term.make(to, {"delay_s" if to == "time_delay" else "time_constant_s": value})
    forced = fit_model(D.design, Model([alt if t is held[0] else t for t in m.terms]))
    return held[0].physics, own, frf_modes.input_path(D.design, forced, 0.05, rec.r)


def test_the_frequency_response_tells_a_sensor_lag_from_a_delay():
    """A first-order lag at fs/20 (cutoff 250 Hz): the rows name it; the response agrees
    (no swap); a model given a delay in its place is told it is a lag, with the lag's
    time constant (1/(2*pi*250 Hz) = 0.637 ms) to 5 %."""
    named, own, swap = _swapped("sensor_lowpass", 20.0, 310302, "time_delay")
    assert named == "sensor_lag" and own is None
    assert swap is not None and swap["physics"] == "sensor_lag", swap
    assert swap["theta"]["time_constant_s"] == pytest.approx(1 / (2 * np.pi * 250.0), rel=0.05)
    ev = swap["evidence"]["terms"]
    assert ev["sensor_lag"]["test_sse"] < ev["time_delay"]["test_sse"] - swap["evidence"]["bound"]


def test_the_frequency_response_tells_a_delay_from_a_sensor_lag():
    """A one-sample delay: the rows name it, the response agrees; a model given a lag in
    its place is told it is a delay of one sample (0.2 ms) to 5 %."""
    named, own, swap = _swapped("delay", 1.0, 310302, "sensor_lag")
    assert named == "time_delay" and own is None
    assert swap is not None and swap["physics"] == "time_delay", swap
    assert swap["theta"]["delay_s"] == pytest.approx(2e-4, rel=0.05)


def test_a_response_neither_term_describes_keeps_the_rows_delay():
    """A half-sample delay in a closed loop driven by a multisine, pink sensor noise: the
    response departs from both a delay and a lag by hundreds of times its random error
    (the loop's bias), and the shortest lag lowered the held-out sum by 0.7 %; scaled by
    the misfit, and at the bound of its range, it does not take the delay's place."""
    rec, _ = recording(Case("delay", 0.5, "pdi", "multisine", 5000.0, noise="pink"), 1310202)
    D = diagnose(rec)
    names = [f.physics for f in D.findings]
    assert "time_delay" in names and "sensor_lag" not in names, [(f.physics, f.params) for f in D.findings]
    assert all(f.frf_path is None for f in D.findings)


def test_a_term_the_response_chooses_replaces_the_rows_and_is_reported(monkeypatch):
    """The diagnosis's wiring: where the frequency path returns another input-path term,
    that term (with the path's parameter) stands in the finding's place, the model is
    proven again with it, and ``report.json``'s evidence carries the path's record."""
    from servo.diagnose import frf_modes
    from servo.diagnose.report import _evidence

    def chosen(design, fit, alpha, instrument=None):
        held = [t for t in fit.model.terms if t.physics == "sensor_lag"]
        if not held:
            return None
        return {"named": "sensor_lag", "physics": "time_delay", "theta": {"delay_s": 6e-4},
                "evidence": {"reason": "chosen here", "named": "sensor_lag"}}

    monkeypatch.setattr(frf_modes, "input_path", chosen)
    rec, _ = recording(Case("sensor_lowpass", 20.0, "pdi", "prbs", 5000.0, noise="white"), 310302)
    D = diagnose(rec)
    f = [f for f in D.findings if f.physics == "time_delay"]
    assert f and not any(g.physics == "sensor_lag" for g in D.findings)
    assert f[0].params["delay_s"] == pytest.approx(6e-4)
    assert D.final_fit.model.get("time_delay").params["delay_s"] == pytest.approx(6e-4)
    assert _evidence(f[0])["frequency_response"]["reason"] == "chosen here"

"""Blind tests on concealed effects: the generator puts one piece of physics into the
simulated drive, the diagnosis (which is not told) must name it, first, with its
parameters; on null recordings (nothing missing) it must find nothing."""
import numpy as np
import pytest

from servo.diagnose.concealed import EFFECTS, concealed_recording
from servo.diagnose.job import Options, diagnose

#: per effect: the parameter to check, its expected value from the truth, and the tolerance
EXPECT = {
    "coulomb_friction": ("Fc", lambda d: d["Fc"], 0.05),
    "viscous_friction": ("B", lambda d: d["B"], 0.05),
    "stiffness": ("K", lambda d: d["K"], 0.05),
    "offset": ("h0", lambda d: d["h0"], 0.05),
    "asymmetric_friction": ("dB", lambda d: d["B"] * d["b_asymmetry"], 0.05),
    "stribeck_friction": ("stribeck_velocity", lambda d: d["stribeck_velocity"], 0.1),
    "hysteresis": ("dahl_length", lambda d: d["Ha"] / d["sigma"], 0.05),
    "resonance": ("frequency_hz", lambda d: d["mode_hz"][0], 0.01),
    "time_delay": ("delay_s", lambda d: d["input_delay_s"], 0.05),
    "sensor_lag": ("cutoff_hz", lambda d: d["sensor_cutoff_hz"], 0.05),
    "input_saturation": ("level", lambda d: d["current_limit"], 0.05),
    "position_dependent_gain": ("kf_linear", lambda d: d["kf_linear"] / d["stroke"], 0.05),
    "cogging": ("period", lambda d: d["cogging_period"], 0.01),
    "quantization": ("step", lambda d: d["position_quantum"], 1e-6),
    "dead_zone": ("width", lambda d: d["dead_zone"], 0.05),
    "cubic_spring": ("k3", lambda d: d["k3"], 0.05),
    # from the dwells at reversals (servo/physics/backlash.py): 0.995 and 1.075 x on 1 and 2 um
    "backlash": ("half_gap", lambda d: d["backlash_half_gap"], 0.15),
}


def test_every_vocabulary_term_has_a_concealed_effect():
    from servo.diagnose.terms import NAMES

    # inertia is a baseline term only; the simulated drive has no drift (servo/physics/drift.py)
    assert set(EFFECTS) == set(NAMES) - {"inertia", "drift"}
    assert set(EXPECT) == set(EFFECTS)


@pytest.mark.parametrize("effect", sorted(EFFECTS))
def test_concealed_effect_is_named_first_with_its_parameters(effect):
    e = EFFECTS[effect]
    rec, truth = concealed_recording(effect, e.clear, seed=11)
    D = diagnose(rec, Options(baseline=truth["baseline"]))
    names = [f.physics for f in D.findings]
    assert names and names[0] == effect, names
    key, value, tol = EXPECT[effect]
    want = value(truth["drive"])
    got = D.findings[0].params[key]
    assert abs(got - want) <= tol * abs(want), (key, got, want)
    f = D.findings[0]
    # proof on the held-out part: the output prediction improves, and for a force term the force error too
    assert f.after["output_nrmse"] < f.before["output_nrmse"]
    if effect != "quantization":
        assert f.after["force_rel_pct"] < f.before["force_rel_pct"]


@pytest.mark.parametrize("seed", range(5))
def test_null_recording_yields_no_finding(seed):
    rec, truth = concealed_recording(None, 0.0, seed=100 + seed)
    D = diagnose(rec)
    assert D.findings == [], [(f.physics, f.params) for f in D.findings]
    # and the baseline it held is the drive's own physics
    p = D.final_fit.combined()
    assert p["inertia"]["J"] == pytest.approx(1e-3, rel=0.01)
    assert p["coulomb_friction"]["Fc"] == pytest.approx(1e-3, rel=0.02)


def test_a_model_file_with_a_wrong_parameter_gets_a_correction(tmp_path):
    """The null drive's own config, with B 40 % low, held fixed against its recording:
    the diagnosis reports a viscous-friction correction of the missing 40 %."""
    from servo.config import Config, to_toml
    from servo.diagnose.concealed import NULL_DRIVE

    rec, truth = concealed_recording(None, 0.0, seed=5)
    wrong = Config().replace(drive={**NULL_DRIVE, "B": 0.6 * NULL_DRIVE["B"], "current_limit": 1.0})
    path = tmp_path / "drive.toml"
    path.write_text(to_toml(wrong))
    D = diagnose(rec, Options(model=str(path)))
    assert [f.physics for f in D.findings] == ["viscous_friction"]
    assert D.findings[0].params["B"] == pytest.approx(0.4 * NULL_DRIVE["B"], rel=0.05)
    assert D.final_fit.combined()["viscous_friction"]["B"] == pytest.approx(NULL_DRIVE["B"], rel=0.03)
    assert not D.baseline.terms[0].free  # held fixed


def test_the_generator_is_deterministic_and_the_effect_is_in_the_drive():
    a, ta = concealed_recording("hysteresis", 1e-4, seed=3)
    b, tb = concealed_recording("hysteresis", 1e-4, seed=3)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.u, b.u)
    assert ta["drive"]["Ha"] == 1e-4 and ta["drive"]["sigma"] == pytest.approx(1e-4 / 3e-6)
    c, _ = concealed_recording(None, 0.0, seed=3)
    assert not np.array_equal(a.x, c.x)

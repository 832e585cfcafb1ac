"""The ``sensor_lag`` term (a first-order low-pass on the position sensor): its physics
on exact signals, its fast screening rows, its place in the simulated drive and the
compensator, and a diagnosis that names it where a delay would not do."""
import math

import numpy as np
import pytest

from servo.config import Config
from servo.diagnose.model import Design, Model, Term
from servo.diagnose.sensor_lag import SensorLag, lag_coefficient, lowpass
from servo.diagnose.signals import make_signals
from servo.diagnose.terms import NAMES, VOCABULARY
from servo.physics import EFFECTS
from servo.identify.regressors import RobustSettings
from servo.io.recording import Recording
from tests.helpers import NO_MODES, quiet_config, simulate_open_loop

BASE = ("inertia", "viscous_friction", "coulomb_friction", "stiffness", "offset")


def _double_integrator(n=20000, fs=10000.0, tau_samples=3.0, seed=3):
    """``J*x'' = u`` sampled exactly under a held ``u`` (a band-limited random force),
    the position measured through the one-pole sensor low-pass, no noise."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / fs
    J = 2e-3
    u = np.convolve(rng.standard_normal(n), np.ones(40) / 40, mode="same") * 1e-3
    x = np.zeros(n)
    v = 0.0
    for k in range(n - 1):  # exact for a held force
        x[k + 1] = x[k] + v * dt + 0.5 * u[k] / J * dt * dt
        v += u[k] / J * dt
    y = lowpass(x, lag_coefficient(tau_samples * dt, dt))
    return Recording(np.arange(n) * dt, u, y, None, source="test"), J


def test_the_term_is_registered_once_with_its_drive_field():
    assert "sensor_lag" in NAMES and isinstance(VOCABULARY["sensor_lag"], SensorLag)
    assert VOCABULARY["sensor_lag"].path.kind == "input"
    assert "sensor_cutoff_hz" in Config().drive.__dataclass_fields__


def test_lowpass_is_the_sensor_filter_and_passes_a_constant():
    z = np.r_[np.full(5, 2.0), np.zeros(10)]
    a = 0.3
    y = lowpass(z, a)
    want = np.empty_like(z)
    want[0] = z[0]
    for k in range(1, z.size):
        want[k] = want[k - 1] + a * (z[k] - want[k - 1])
    assert np.allclose(y, want, rtol=0, atol=1e-15)
    assert np.all(y[:5] == 2.0)  # started at rest
    assert lag_coefficient(0.0, 1.0) == 1.0 and np.array_equal(lowpass(z, 1.0), z)


def test_the_lagged_force_balances_a_lagged_double_integrator_exactly():
    """The physics the term rests on: the lag commutes with the rows' linear chain, so
    for ``J*x'' = u`` measured through ``L``, ``J*y''`` equals the rows of ``L(u)`` (to
    the rows' end effects), while the unfiltered force leaves tens of percent."""
    rec, J = _double_integrator()
    sig = make_signals(rec, RobustSettings())
    d = Design(sig)
    acc = sig.rows(sig.af) * J
    inner = slice(40, -40)
    plain = d.target_raw(Model())
    lagged = d.target_raw(Model([Term.make("sensor_lag", {"time_constant_s": 3.0 * sig.dt})]))
    scale = np.linalg.norm(acc[inner])
    assert np.linalg.norm((acc - lagged)[inner]) < 1e-6 * scale
    assert np.linalg.norm((acc - plain)[inner]) > 0.05 * scale


def test_the_screening_rows_equal_the_exact_chain_away_from_the_ends():
    rec, _ = _double_integrator(n=12000, tau_samples=1.0)
    sig = make_signals(rec, RobustSettings())
    d = Design(sig)
    for tau in (1.5, 4.0, 15.0):
        th = {"time_constant_s": tau * sig.dt}
        fast = VOCABULARY["sensor_lag"].search.screen_target(d, Model(), th)
        exact = sig.force_rows(SensorLag.path.transform(sig.u, th, sig.dt))
        s = np.abs(exact).max()
        assert np.max(np.abs(fast - exact)[100:-100]) < 1e-9 * s
        assert fast.shape == exact.shape


def test_the_grid_starts_where_a_lag_stops_being_a_delay():
    rec, _ = _double_integrator(n=12000)
    sig = make_signals(rec, RobustSettings())
    g = [th["time_constant_s"] / sig.dt for th in VOCABULARY["sensor_lag"].grid(Design(sig), Model())]
    w_e = 2 * math.pi * 0.4 / sig.settings.decimate
    assert g[0] * w_e == pytest.approx(SensorLag.DELAY_LIKE)
    assert g[-1] == pytest.approx(2.0 * sig.settings.decimate)
    assert np.all(np.diff(np.log2(g)) <= 1.0 / SensorLag.PER_OCTAVE + 1e-9)


def test_the_drive_sensor_filters_the_measured_position_and_nothing_else():
    """``sensor_cutoff_hz`` puts the same one-pole on the drive's measured position; the
    rigid motion is unchanged, and 0 keeps the measurement bit for bit."""
    fs = 50_000.0
    u = 2e-3 * np.sign(np.sin(2 * np.pi * 40 * np.arange(4000) / fs))
    base, _ = simulate_open_loop(quiet_config(**NO_MODES), u)
    off, _ = simulate_open_loop(quiet_config(**NO_MODES, sensor_cutoff_hz=0.0), u)
    on, p = simulate_open_loop(quiet_config(**NO_MODES, sensor_cutoff_hz=2000.0), u)
    assert np.array_equal(base, off)
    assert np.array_equal(base[:3], on[:3])  # x, v, H
    a = 1 - math.exp(-2 * math.pi * 2000.0 / fs)
    assert p.params[0]["sensor_a"] == pytest.approx(a)
    assert np.allclose(on[3], lowpass(base[3], a), rtol=0, atol=1e-15)


def test_drive_mapping_round_trip():
    phys, drive_map = VOCABULARY["sensor_lag"], EFFECTS["sensor_lag"].drive_map
    d = Config().replace(drive={"sensor_cutoff_hz": 1500.0}).drive
    [(theta, coef)] = drive_map.from_drive(d)
    assert coef == () and theta["time_constant_s"] == pytest.approx(1 / (2 * math.pi * 1500.0))
    P = {"sensor_lag": phys.physical(theta, coef)}
    assert drive_map.to_drive(P, None) == {"sensor_cutoff_hz": pytest.approx(1500.0)}
    assert drive_map.from_drive(Config().drive) == [] and drive_map.absent == {"sensor_cutoff_hz": 0.0}


def test_compensate_says_what_to_do_about_a_sensor_lag(tmp_path):
    from servo.compensate.job import compensate
    from servo.compensate.model import NOT_CANCELLABLE
    from servo.config import to_toml

    p = tmp_path / "drive.toml"
    p.write_text(to_toml(Config().replace(drive={"sensor_cutoff_hz": 3000.0})))
    prop = compensate(p, Config())
    advice = {t.name: t.advice for t in prop.not_cancelled}
    assert advice["sensor_lag"] == NOT_CANCELLABLE["sensor_lag"]
    assert "bandwidth" in advice["sensor_lag"] and "observer" in advice["sensor_lag"]


def test_a_long_sensor_lag_is_named_with_its_cutoff_where_a_delay_is_not(tmp_path):
    """Proving ground (its own integrator): a lead-lag loop with seek strokes at 1 kHz and
    a sensor cutoff of fs/20 (tau 3.2 samples).  ``sensor_lag`` is named first, with
    its cutoff, and the model reaches its noise floor; a delay in its place leaves the
    residual several times the floor."""
    from servo.diagnose.job import diagnose
    from studies.proving.cases import Case, recording

    rec, truth = recording(Case("sensor_lowpass", 20.0, "leadlag", "seeks", 1000.0), 70003)
    D = diagnose(rec)
    assert [f.physics for f in D.findings][:1] == ["sensor_lag"], [f.physics for f in D.findings]
    assert D.findings[0].params["cutoff_hz"] == pytest.approx(1000.0 / 20.0, rel=0.03)
    assert D.verdict["verdict"] == "explained"
    assert D.verdict["final_checks"]["level"]["ratio"] < 1.2 < D.verdict["baseline_checks"]["level"]["ratio"]
    ts = D.rounds[0]["scores"]
    lag, delay = (next(s for s in ts if s.physics == n) for n in ("sensor_lag", "time_delay"))
    assert lag.S1.sum() < 0.5 * delay.S1.sum()  # the held-out error a delay leaves is twice the lag's at least
    # the final model written as a drive config holds the lag, and held against the same
    # recording it leaves nothing to find
    from servo.diagnose.job import Options
    from servo.diagnose.report import build_report, write_drive_toml

    assert write_drive_toml(build_report(D), tmp_path)
    held = diagnose(rec, Options(model=str(tmp_path / "final_model.toml")))
    assert [t.physics for t in held.baseline.terms if t.physics == "sensor_lag"] == ["sensor_lag"]
    assert held.findings == [] and held.verdict["verdict"] == "consistent"

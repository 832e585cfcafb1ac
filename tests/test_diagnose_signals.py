"""The rows a diagnosis fits: exact for a zero-order-hold double integrator, the
uncertain-direction mask, the distance since reversal, the prediction kernel."""
import numpy as np
import pytest

from kernels.plant import PLANT_PARAMS, PLANT_STATE, plant_measure, plant_step
from kernels.predict import multistep
from servo.diagnose.signals import align, derivative, distance_since_reversal, make_signals, second_difference
from servo.identify import RobustSettings, robust_regression
from servo.io.recording import Recording


def zoh_double_integrator(n=20000, dt=1e-3, J=2.0, seed=0):
    """Exact samples of J*x'' = u under a held u (smooth random input)."""
    rng = np.random.default_rng(seed)
    u = np.convolve(rng.standard_normal(n), np.ones(50) / 50, mode="same")
    x, v = np.zeros(n), np.zeros(n)
    for k in range(n - 1):
        a = u[k] / J
        x[k + 1] = x[k] + v[k] * dt + 0.5 * a * dt * dt
        v[k + 1] = v[k] + a * dt
    return np.arange(n) * dt, u, x, J


def test_second_difference_matches_the_aligned_held_force_exactly():
    t, u, x, J = zoh_double_integrator()
    a = second_difference(x, t[1] - t[0])
    assert np.max(np.abs(J * a[1:-1] - align(u)[1:-1])) < 1e-9 * np.max(np.abs(u))
    # a derivative of a derivative is not: it is low at high frequency
    g = np.gradient(np.gradient(x, t[1]), t[1])
    assert np.max(np.abs(J * g[2:-2] - align(u)[2:-2])) > 1e-3 * np.max(np.abs(u))


def test_rows_fit_the_double_integrator_to_rounding():
    """Through the whole path (Butterworth, difference, parallel decimation) J is exact
    and the residual is negligible."""
    t, u, x, J = zoh_double_integrator()
    sig = make_signals(Recording(t, u, x))
    A = sig.base_columns(("J",))[:, 0]
    y = sig.force_rows()
    Jhat = (A @ y) / (A @ A)
    assert abs(Jhat - J) / J < 1e-7  # filter start-up at the ends only
    mid = slice(60, -60)  # away from the filters' start-up transients
    assert np.max(np.abs(y - J * A)[mid]) < 1e-8 * np.max(np.abs(y))


def test_derivative_is_sixth_order():
    dt = 1e-3
    t = np.arange(4000) * dt
    f = 40.0  # w*dt = 0.25, the rows' band edge for decimation by 10
    z = np.sin(2 * np.pi * f * t)
    d = derivative(z, dt)[10:-10]
    exact = 2 * np.pi * f * np.cos(2 * np.pi * f * t)[10:-10]
    assert np.max(np.abs(d - exact)) / (2 * np.pi * f) < 3e-6
    assert np.max(np.abs(np.gradient(z, dt)[10:-10] - exact)) / (2 * np.pi * f) > 5e-3


def test_columns_follow_the_identify_path_for_position_and_force():
    """Same trimming, decimation and row instants as servo identify's robust path."""
    t, u, x, _ = zoh_double_integrator(5000)
    sig = make_signals(Recording(t, u, x))
    reg = robust_regression(t, x, u, t[1], ("K", "h0"))
    assert np.array_equal(sig.t_rows, reg.t)
    assert np.allclose(sig.base_columns(("K", "h0")), reg.Phi, rtol=0, atol=1e-12 * np.max(np.abs(x)))


def test_a_stuck_interval_is_masked_and_motion_is_not():
    dt = 1e-3
    t = np.arange(20000) * dt
    x = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    x[8000:9000] = x[8000]  # stuck for 1 s
    x += np.random.default_rng(1).normal(0, 1e-7, t.size)
    sig = make_signals(Recording(t, np.sin(t), x))
    stuck = (sig.t_rows > 8.0) & (sig.t_rows < 9.0)
    assert not sig.valid[stuck].any()
    # rows moving fast, away from the stuck interval and the reversals, are all usable
    phase = (sig.t_rows * 0.5) % 0.5
    fast = (np.abs(sig.v_rows) > 0.5 * 0.0314) & ((sig.t_rows < 7.5) | (sig.t_rows > 9.5))
    assert sig.valid[fast].all()
    assert 0.5 < sig.valid.mean() < 0.75  # each reversal costs the filter's reach, 0.3 s
    assert sig.noise_x == pytest.approx(1e-7, rel=0.1)  # robust to the kinks of the stuck interval
    assert phase.size == sig.m


def test_distance_since_reversal():
    t = np.linspace(0, 1, 1001)
    x = np.where(t < 0.5, t, 1.0 - t)  # up to 0.5, then back down
    v = np.gradient(x, t)
    d = distance_since_reversal(x, v, 1e-6)
    assert d[200] == pytest.approx(0.2)
    assert d[700] == pytest.approx(0.2, abs=2e-3)


def test_too_short_a_recording_is_refused():
    from servo.identify import IdentificationError

    t, u, x, _ = zoh_double_integrator(1500)
    with pytest.raises(IdentificationError, match="too short to diagnose"):
        make_signals(Recording(t, u, x), RobustSettings())


def test_multistep_reproduces_the_plant_from_exact_states():
    """Predictions from the plant's own states equal the plant's trajectory."""
    from servo.config import Config
    from servo.runtime.simplant import build_plant

    cfg = Config().replace(drive=dict(mode_hz=[], mode_zeta=[], mode_gain=[], input_delay_s=0.0, Fc=1e-3, Fs=1e-3,
                                      position_noise=0.0, position_quantum=0.0))  # fmt: skip
    p = build_plant(cfg.drive, cfg.dt)
    n = 3000
    u = 0.01 * np.sin(2 * np.pi * 50 * np.arange(n) * cfg.dt) + p.u_hold
    xs, vs, Hs = np.zeros(n + 1), np.zeros(n + 1), np.zeros(n + 1)
    for k in range(n):
        st = p.state[0]
        xs[k], vs[k], Hs[k] = st["x"], st["v"], st["H"]
        plant_step(p.state, p.params, p.q, p.mab, p.ubuf, u[k], 0.0)
    xs[n] = p.state[0]["x"]
    starts = np.arange(0, n - 100, 100, dtype=np.int64)
    out = np.zeros((starts.size, 100))
    ps = np.zeros(1, PLANT_STATE)
    multistep(ps, p.params, np.zeros((0, 2)), p.mab, p.gain, np.zeros(2), u, xs[starts], vs[starts], Hs[starts],
              np.zeros((starts.size, 0, 2)), starts, 100, out)  # fmt: skip
    idx = starts[:, None] + np.arange(1, 101)[None, :]
    assert np.max(np.abs(out - xs[idx])) < 1e-15
    assert PLANT_PARAMS is not None and plant_measure is not None


def test_the_sign_column_is_the_triangular_average_the_acceleration_sees():
    """At a zero crossing between samples, the Coulomb column at the two samples around
    it is the average of sgn(v) with the triangular weight of the second difference,
    for the crossing placed by linear interpolation; elsewhere it is the sign."""
    from servo.diagnose.signals import held_sign

    for s0 in (0.1, 0.5, 0.9):
        v = np.arange(-5.0, 6.0) - s0  # crossing at t = s0 between samples 5 and 6
        hs = held_sign(v)
        s = np.linspace(-1, 1, 200001)
        w = 1 - np.abs(s)
        for k in range(11):
            exact = np.trapezoid(w * np.sign(k - 5 + s - s0), s) / np.trapezoid(w, s)
            assert hs[k] == pytest.approx(exact, abs=1e-5)


@pytest.mark.parametrize("placed", [-1.9, -1.2, -0.6, 0.2, 0.95, 1.4])
def test_a_crossing_placed_away_from_the_sign_change_moves_every_sample_between(placed):
    """The reversal's fit may place the friction's switch up to two samples from where
    the filtered velocity changes sign (a fast reversal of the outside suite's null: 1.0-1.4
    samples before it).  Every sample between the two takes the placed crossing's side,
    not only those within one sample of it: a sample left with the filtered velocity's
    sign carried a wrong Coulomb force (2 Fc over one sample, the null's rows at 19-25 x
    their noise floor)."""
    from servo.diagnose.signals import held_sign

    v = np.arange(-8.0, 9.0) - 0.4  # the sign changes between samples 8 and 9
    t0 = 8.0 + placed  # samples from the last one before the sign change
    hs = held_sign(v, np.array([t0]))
    s = np.linspace(-1, 1, 200001)
    w = 1 - np.abs(s)
    for k in range(v.size):
        exact = np.trapezoid(w * np.sign(k + s - t0), s) / np.trapezoid(w, s)
        assert hs[k] == pytest.approx(exact, abs=1e-5), k
    # the column's integral is the Coulomb force's impulse with the switch at t0
    assert hs[1:-1].sum() == pytest.approx(v.size - 1 - 2 * t0, abs=1e-5)


def test_a_reversal_is_placed_where_the_velocity_crosses_zero_not_where_the_filtered_one_does():
    """Friction that flips at a reversal makes the acceleration jump there; the
    zero-phase filter spreads the kink and the filtered velocity crosses zero late.
    The fitted crossing recovers the true one; linear interpolation of the filtered
    velocity is late by a fraction of a sample, always on the same side."""
    from scipy import signal

    from servo.diagnose.signals import reversal_times

    s = RobustSettings()
    fs = 1000.0
    b, a = signal.butter(s.butter_order, s.cutoff(fs) / (fs / 2))
    for t0, a1, a2 in ((500.3, -2.0, -1.0), (500.75, 1.5, 0.5), (500.1, -1.2, -0.2)):
        k = np.arange(1001.0)
        tau = (k - t0) / fs
        x = np.where(tau < 0, a1 * tau**2 / 2, a2 * tau**2 / 2)
        vf = derivative(signal.filtfilt(b, a, x, padlen=3 * s.butter_order), 1 / fs)
        c = np.flatnonzero(np.sign(vf[1:]) * np.sign(vf[:-1]) < 0)
        assert c.size == 1
        linear = c[0] + vf[c[0]] / (vf[c[0]] - vf[c[0] + 1])
        assert linear - t0 > 0.2  # late
        assert reversal_times(vf, s, fs, 1e-9)[0] == pytest.approx(t0, abs=0.03)

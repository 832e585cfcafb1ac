"""The simulated drive: against solve_ivp, sticking, delay, limits, sensor."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from kernels.plant import plant_measure
from servo.runtime.simdriver import SimDriver
from servo.runtime.simplant import build_plant, split_delay
from tests.helpers import NO_MODES, quiet_config, simulate_open_loop


def reference_solution(cfg, u, u_hold):
    """The drive of docs/model.md as one ODE (rigid body, Dahl eq. 6 in time, modes, delayed
    zero-order-hold input) integrated by DOP853 at rtol 1e-12 between input switches.
    Returns (n+1, 4): rigid x, v, H and measured position at the sample instants."""
    d, dt, tau = cfg.drive, cfg.dt, cfg.drive.input_delay_s
    w = 2 * np.pi * np.asarray(d.mode_hz)
    z, g, nm = np.asarray(d.mode_zeta), np.asarray(d.mode_gain), len(d.mode_hz)

    def u_at(t):
        k = math.floor((t - tau) / dt + 1e-9)
        return u_hold if k < 0 else u[k]

    def rhs(t, y):
        x, v, H = y[:3]
        s = np.sign(v)
        dH = d.sigma * (1 - s * H / d.Ha) ** d.alpha * v if s != 0 else 0.0
        uu = u_at(t)
        a = (uu - d.B * v - H - d.K * x - d.h0) / d.J
        q, qd = y[3 : 3 + nm], y[3 + nm :]
        return np.concatenate([[v, a, dH], qd, uu / d.J - 2 * z * w * qd - w * w * q])

    n = len(u)
    cuts = sorted({k * dt for k in range(n + 1)} | {k * dt + tau for k in range(n) if k * dt + tau < n * dt})
    y = np.zeros(3 + 2 * nm)
    y[0] = d.initial_position
    y[3 : 3 + nm] = u_hold / (d.J * w * w)  # modes at rest under the holding current
    out = np.zeros((n + 1, 4))
    out[0] = (y[0], 0.0, 0.0, y[0] + g @ y[3 : 3 + nm])
    for a, b in zip(cuts[:-1], cuts[1:]):
        y = solve_ivp(rhs, (a, b), y, method="DOP853", rtol=1e-12, atol=1e-18).y[:, -1]
        k = round(b / dt)
        if abs(b - k * dt) < 1e-12:
            out[k] = (y[0], y[1], y[2], y[0] + g @ y[3 : 3 + nm])
    return out


def test_plant_matches_solve_ivp_on_a_smooth_case():
    """A push above breakaway from rest: no velocity reversal, all six modes ringing,
    the 10 us delay inside the sample.  Agreement to ~1e-11 of the motion (float64
    resolution of the absolute position)."""
    cfg = quiet_config()
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    u = np.full(120, u_hold + 3e-3)
    sim, _ = simulate_open_loop(cfg, u)
    ref = reference_solution(cfg, u, u_hold)
    span = np.ptp(ref[:, 0])
    assert np.abs(sim[0] - ref[:, 0]).max() < 1e-10 * span
    assert np.abs(sim[3] - ref[:, 3]).max() < 1e-10 * np.ptp(ref[:, 3])
    assert np.abs(sim[2] - ref[:, 2]).max() < 1e-10 * cfg.drive.Ha


@pytest.mark.slow
def test_plant_matches_solve_ivp_across_velocity_reversals():
    """A 500 Hz sine that reverses the motion every millisecond: the Dahl state across
    reversals agrees to ~1e-5 (a reversal inside a sub-step is resolved to the sub-step)."""
    cfg = quiet_config()
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    u = u_hold + 2e-3 * np.sin(2 * np.pi * 500 * np.arange(250) * cfg.dt)
    sim, _ = simulate_open_loop(cfg, u)
    ref = reference_solution(cfg, u, u_hold)
    assert np.count_nonzero(np.diff(np.sign(ref[1:, 1])) != 0) >= 3
    assert np.abs(sim[0] - ref[:, 0]).max() < 1e-4 * np.ptp(ref[:, 0])
    assert np.abs(sim[2] - ref[:, 2]).max() < 1e-4 * cfg.drive.Ha


def test_coulomb_force_below_breakaway_holds_the_arm_exactly_still():
    cfg = quiet_config(Fc=2e-3, Fs=3e-3)
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    sim, _ = simulate_open_loop(cfg, np.full(20000, u_hold + 2.5e-3))  # 0.4 s, 2.5 mA < 3 mA
    assert np.all(sim[1] == 0.0)  # no chatter: not a single nonzero velocity
    assert np.all(sim[0] == sim[0, 0])  # no creep: not a bit of motion


def test_coulomb_arm_breaks_away_slides_and_sticks_again():
    cfg = quiet_config(Fc=2e-3, Fs=3e-3)
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    u = np.concatenate([np.full(2000, u_hold + 4.5e-3), np.full(20000, u_hold + 1e-3)])
    sim, _ = simulate_open_loop(cfg, u)
    assert sim[0, 2000] - sim[0, 0] > 1e-4  # above breakaway it slides
    stopped = np.flatnonzero(sim[1] == 0.0)
    first = stopped[stopped > 2000][0]
    assert np.all(sim[1, first:] == 0.0) and np.ptp(sim[0, first:]) == 0.0


def test_dahl_pivot_below_breakaway_deflects_rings_down_and_stays():
    """The default drive has only the Dahl pivot: below Ha it is a hysteretic spring.  A
    slow ramp to 0.8*Ha deflects the arm along the Dahl virgin curve; then the arm rings at
    the pivot mode, the ringing dies out and the position stops (the single-state Dahl
    model ratchets a little while it rings: bounded, and it stops with the ringing)."""
    cfg = quiet_config(**NO_MODES)
    d, dt = cfg.drive, cfg.dt
    u_hold = build_plant(d, dt).u_hold
    F, nr, nh = 0.8 * d.Ha, int(0.3 / dt), int(4.0 / dt)
    ramp = F * 0.5 * (1 - np.cos(np.pi * np.minimum(np.arange(nr + nh) / nr, 1.0)))
    sim, _ = simulate_open_loop(cfg, u_hold + ramp)
    x, v = sim[0] - sim[0, 0], sim[1]
    static = brentq(lambda s: d.Ha * (1 - math.exp(-d.sigma * s / d.Ha)) + d.K * s - F, 0.0, 1e-3)
    assert x[nr] == pytest.approx(static, rel=0.01)  # on the Dahl curve at the end of the ramp
    sec = int(1 / dt)
    drift = [abs(x[nr + (i + 1) * sec] - x[nr + i * sec]) for i in range(4)]
    assert drift[3] < 0.05 * drift[0]  # the drift dies out...
    assert x[-1] < 1.5 * static  # ...bounded within the pre-sliding range
    assert np.abs(v[-sec:]).max() < 0.1 * np.abs(v[nr : nr + sec]).max()  # ringing decays
    pivot_hz = math.sqrt(2 * d.sigma / d.J) / (2 * math.pi)  # stiffest branch of the spring
    flips = np.count_nonzero(np.diff(np.sign(v[-sec:])) != 0)
    assert flips < 2 * pivot_hz * 1.2  # ringing, not chatter (chatter would be ~1 per sample)


def test_arm_at_equilibrium_stays_put():
    cfg = quiet_config()
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    sim, _ = simulate_open_loop(cfg, np.full(50000, u_hold))
    assert np.abs(sim[0] - sim[0, 0]).max() < 1e-15


def test_force_above_the_pivot_friction_slides_the_arm():
    cfg = quiet_config(**NO_MODES)
    d = cfg.drive
    u_hold = build_plant(d, cfg.dt).u_hold
    sim, _ = simulate_open_loop(cfg, np.full(5000, u_hold + 3 * d.Ha))  # 0.1 s
    # J*x'' = 3*Ha - B*x' - K*x - H with the Dahl force H rising to Ha within microns
    def rhs(t, y):
        return [y[1], (3 * d.Ha - d.B * y[1] - d.K * y[0] - y[2]) / d.J, d.sigma * (1 - y[2] / d.Ha) * y[1]]

    ref = solve_ivp(rhs, (0, 0.1 + 10e-6), [0.0, 0.0, 0.0], rtol=1e-11, atol=1e-16, t_eval=[0.1 - 10e-6])
    assert sim[0, -1] - sim[0, 0] == pytest.approx(ref.y[0, -1], rel=1e-6)  # (the 10 us input delay)
    assert ref.y[0, -1] > 1000 * d.Ha / d.sigma  # far beyond pre-sliding: it slid


def test_input_delay_is_exact():
    """A current step issued at tick 10 starts to move the arm 10 us later: the sample at
    tick 11 has moved by exactly the motion of the last 10 us of that period."""
    cfg = quiet_config(**NO_MODES, input_delay_s=30e-6)  # 1.5 samples
    assert split_delay(30e-6, cfg.dt) == (1, pytest.approx(10e-6))
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    u = np.full(20, u_hold)
    u[10:] += 5e-3
    sim, _ = simulate_open_loop(cfg, u)
    assert np.all(sim[0, :12] == sim[0, 0])  # applied from t = 10*dt + 30 us = 11.5 dt
    a = 5e-3 / cfg.drive.J
    assert sim[0, 12] - sim[0, 0] == pytest.approx(0.5 * a * (10e-6) ** 2, rel=1e-3)


def test_amplifier_current_limit():
    cfg = quiet_config(**NO_MODES, current_limit=0.01)
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    sim, _ = simulate_open_loop(cfg, np.full(100, 10.0))
    limited, _ = simulate_open_loop(cfg, np.full(100, 0.01))
    np.testing.assert_array_equal(sim[0], limited[0])
    assert u_hold < 0.01


def test_sensor_noise_is_seeded_and_quantised():
    cfg = quiet_config(position_noise=5e-9, position_quantum=1e-9, velocity_noise=1e-6)
    reads = []
    for seed in (7, 7, 8):
        drv = SimDriver(cfg.replace(run={"seed": seed}))
        with drv:
            drv.configure()
            drv.activate()
            xs = []
            for _ in range(3000):
                xs.append(drv.read())
                drv.write(drv.applied_current)
        reads.append(np.array(xs))
    np.testing.assert_array_equal(reads[0], reads[1])
    assert not np.array_equal(reads[0], reads[2])
    x = reads[0][:, 0]
    np.testing.assert_allclose(x / 1e-9, np.round(x / 1e-9), atol=1e-6)
    assert np.std(x) == pytest.approx(5e-9, rel=0.1)
    assert np.std(reads[0][:, 1]) == pytest.approx(1e-6, rel=0.1)


def test_drive_without_velocity_sensor_reads_nan():
    cfg = quiet_config(measures_velocity=False)
    p = build_plant(cfg.drive, cfg.dt)
    assert math.isnan(plant_measure(p.state, p.params, p.q, p.gain, 0.0, 0.0)[1])

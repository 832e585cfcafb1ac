"""Compensator (eq. 8-9), its regime switch and motion signals, and the PI holding loop."""
import math

import numpy as np
import pytest

from kernels.compensator import FAST, SLOW, compensate, direction, regime_switch, velocity_estimate
from kernels.holding import holding_pi, holding_pi_bumpless
from servo.config import Config
from servo.runtime.controller import Controller

B, FC, K, H0 = 2e-3, 1e-3, 0.1, 2e-3


def test_compensate_is_eq9_in_both_regimes():
    x, v, s, H = 3e-6, -4e-4, -1.0, -0.7e-3
    assert compensate(FAST, x, v, s, H, B, FC, K, H0) == pytest.approx(B * v + FC * s + K * x + H0, rel=1e-15)
    assert compensate(SLOW, x, v, s, H, B, FC, K, H0) == pytest.approx(B * v + H + K * x + H0, rel=1e-15)


def test_switch_needs_speed_and_distance_and_has_hysteresis():
    v_on, v_off, xi_on = 2e-3, 1e-3, 1.25e-5
    assert regime_switch(SLOW, 5e-3, 1e-6, 0.0, v_on, v_off, xi_on) == SLOW  # fast but near the turnaround
    assert regime_switch(SLOW, 1.5e-3, 1e-4, 0.0, v_on, v_off, xi_on) == SLOW  # far but slow
    assert regime_switch(SLOW, 2.5e-3, 2e-5, 0.0, v_on, v_off, xi_on) == FAST
    assert regime_switch(FAST, 1.5e-3, 2e-5, 0.0, v_on, v_off, xi_on) == FAST  # inside the hysteresis band
    assert regime_switch(FAST, 0.5e-3, 2e-5, 0.0, v_on, v_off, xi_on) == SLOW
    assert regime_switch(FAST, 5e-3, 2e-5, 1.0, v_on, v_off, xi_on) == SLOW  # a turnaround


def test_switch_does_not_chatter_on_a_noisy_speed_near_the_threshold():
    rng = np.random.default_rng(0)
    speeds = 1.9e-3 + 0.2e-3 * rng.standard_normal(5000)  # straddles v_on, stays above v_off
    assert speeds.min() > 1e-3 and (speeds > 2e-3).sum() > 100
    regime, changes = SLOW, 0
    for v in speeds:
        new = regime_switch(regime, v, 1e-4, 0.0, 2e-3, 1e-3, 1.25e-5)
        changes += new != regime
        regime = new
    assert changes == 1


def test_direction_deadband():
    s = 1.0
    for v, expected in [(1e-6, 1.0), (-4e-6, 1.0), (-6e-6, -1.0), (4e-6, -1.0), (6e-6, 1.0)]:
        s = direction(s, v, 5e-6)
        assert s == expected


def test_velocity_estimator_is_exact_on_a_ramp_and_low_passes_noise():
    dt, a = 2e-5, math.exp(-2 * math.pi * 2000 * 2e-5)
    v, x_prev = 0.0, 0.0
    for k in range(1, 400):
        x = 3e-3 * k * dt
        v = velocity_estimate(v, x, x_prev, dt, a)
        x_prev = x
    assert v == pytest.approx(3e-3, rel=1e-12)
    rng = np.random.default_rng(1)
    xs = 1e-9 * rng.standard_normal(20000)
    raw = np.diff(xs) / dt
    est, vs = 0.0, []
    for k in range(1, xs.size):
        est = velocity_estimate(est, xs[k], xs[k - 1], dt, a)
        vs.append(est)
    assert np.std(vs) < 0.5 * np.std(raw)


def test_holding_pi_equation_and_integrator():
    u, integ = holding_pi(2e-6, 1e-6, 3e-4, 1e-4, 5e-5, 400.0, 5e4, 0.9, 2e-5, -1.0, 1.0)
    assert u == pytest.approx(400.0 * 1e-6 + 1e-4 - 0.9 * 3e-4 + 5e-5, rel=1e-14)
    assert integ == pytest.approx(1e-4 + 5e4 * 2e-5 * 2e-6, rel=1e-14)


def test_holding_pi_anti_windup_and_limits():
    integ = 0.0
    for _ in range(10000):  # a large error held for 0.2 s against a 0.05 A limit
        u, integ = holding_pi(1e-3, 1e-3, 0.0, integ, 0.0, 400.0, 5e4, 0.0, 2e-5, -0.05, 0.05)
        assert -0.05 <= u <= 0.05
    assert integ == pytest.approx(0.0)  # saturated from the first sample: never integrated
    # once the error reverses the output leaves the limit at once (nothing to unwind)
    u, integ = holding_pi(-1e-5, -1e-5, 0.0, integ, 0.0, 400.0, 5e4, 0.0, 2e-5, -0.05, 0.05)
    assert u == pytest.approx(-4e-3)


def test_bumpless_start_first_output_equals_applied_current():
    cfg = Config()
    ctl = Controller(cfg)
    x0, u_now = 1.5e-3, 0.0123
    ctl.start(x0, 0.0, u_now)
    u = ctl.tick(x0, 0.0, 0.0, 0.0)
    assert u == pytest.approx(u_now, abs=1e-12)
    assert holding_pi_bumpless(0.3, 0.0, 0.0, 400.0, 0.9) == 0.3


def test_total_command_respects_the_current_limit():
    cfg = Config().replace(controller={"current_limit": 0.01})
    ctl = Controller(cfg)
    ctl.start(0.0, 0.0, 0.0)
    for k in range(200):
        u = ctl.tick(0.0, 0.0, 1e-3, 0.0)  # a 1 mm reference step
        assert abs(u) <= 0.01


def test_controller_uses_the_estimator_when_the_drive_has_no_velocity():
    cfg = Config()
    ctl = Controller(cfg)
    ctl.start(0.0, math.nan, 0.0)
    dt = cfg.dt
    for k in range(1, 2000):
        ctl.tick(1e-3 * k * dt, math.nan, 0.0, 0.0)
    assert ctl.stage_state[0]["v"] == pytest.approx(1e-3, rel=1e-9)

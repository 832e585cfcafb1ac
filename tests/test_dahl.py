"""Dahl hysteresis (eq. 6-7): closed form vs differential form vs incremental form."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from kernels.dahl import dahl_closed, dahl_flow, dahl_slope, dahl_update

SIGMA, HA = 320.0, 1.0e-3


@pytest.mark.parametrize("alpha", [0.5, 1.0, 2.0, 3.5])
@pytest.mark.parametrize("s,H_r", [(1.0, 0.0), (1.0, -0.8e-3), (-1.0, 0.6e-3), (-1.0, -0.3e-3)])
def test_closed_form_matches_differential_form(alpha, s, H_r):
    """Eq. (7) from the turnaround equals the numerical integral of eq. (6) in x."""
    x_r = 2.0e-6
    xs = x_r + s * np.linspace(0.0, 5.0 * HA / SIGMA, 60)
    sol = solve_ivp(
        lambda x, H: [dahl_slope(H[0], s, SIGMA, HA, alpha)],
        (xs[0], xs[-1]), [H_r], t_eval=xs, rtol=1e-12, atol=1e-16, method="DOP853",
    )  # fmt: skip
    closed = np.array([dahl_closed(x, x_r, H_r, s, SIGMA, HA, alpha) for x in xs])
    np.testing.assert_allclose(closed, sol.y[0], rtol=0, atol=1e-10 * HA)


def test_alpha_one_is_the_exponential():
    H = dahl_closed(3e-6, 1e-6, -0.5e-3, 1.0, SIGMA, HA, 1.0)
    expected = HA - (HA + 0.5e-3) * math.exp(-SIGMA * 2e-6 / HA)
    assert H == pytest.approx(expected, rel=1e-14)


@settings(max_examples=200, deadline=None)
@given(
    alpha=st.floats(0.2, 4.0),
    s=st.sampled_from([-1.0, 1.0]),
    H_r=st.floats(-0.999e-3, 0.999e-3),
    steps=st.lists(st.floats(0.0, 2e-6), min_size=1, max_size=40),
)
def test_incremental_form_agrees_with_closed_form(alpha, s, H_r, steps):
    """Stepping eq. (6) sample by sample lands where eq. (7) from the turnaround does."""
    x_r, H, x = 0.0, H_r, 0.0
    for dx in steps:
        H = dahl_flow(H, s * dx, s, SIGMA, HA, alpha)
        x += s * dx
    assert H == pytest.approx(dahl_closed(x, x_r, H_r, s, SIGMA, HA, alpha), abs=1e-12 * HA)


@settings(max_examples=200, deadline=None)
@given(alpha=st.floats(0.2, 4.0), H=st.floats(-0.99e-3, 0.99e-3), dx=st.floats(-3e-6, 3e-6))
def test_estimate_stays_saturated_within_plus_minus_Ha(alpha, H, dx):
    for s in (-1.0, 1.0):
        out = dahl_flow(H, dx, s, SIGMA, HA, alpha)
        assert -HA <= out <= HA


def test_slope_at_a_virgin_turnaround_is_sigma_and_vanishes_at_the_asymptote():
    assert dahl_slope(0.0, 1.0, SIGMA, HA, 1.0) == SIGMA
    assert dahl_slope(HA, 1.0, SIGMA, HA, 1.0) == 0.0
    assert dahl_slope(HA, -1.0, SIGMA, HA, 1.0) == 2.0 * SIGMA  # reversing from +Ha


def test_alpha_below_one_reaches_the_asymptote_in_finite_distance():
    # y^(1-a) = 1 - (1-a)*sigma*xi/Ha = 0 at xi = Ha/((1-a)*sigma)
    xi = HA / (0.5 * SIGMA)
    assert dahl_flow(0.0, 1.01 * xi, 1.0, SIGMA, HA, 0.5) == HA
    assert dahl_flow(0.0, 0.9 * xi, 1.0, SIGMA, HA, 0.5) < HA


def test_update_memorises_only_the_latest_turnaround_at_the_extreme():
    """A sine path: the estimator (direction from the exact velocity) reproduces the
    exact Dahl path, and after each reversal H_r is the value at the extreme."""
    t = np.linspace(0.0, 2.0, 4001)
    x = 3e-6 * np.sin(2 * np.pi * t) * (1 + 0.3 * t)
    v = np.gradient(x, t)
    s, x_r, H_r, x_ext, H = 1.0, x[0], 0.0, x[0], 0.0
    H_true, s_true = 0.0, 1.0
    for k in range(1, len(t)):
        s_new = 1.0 if v[k] > 0 else -1.0
        s, x_r, H_r, x_ext, H = dahl_update(x[k], s_new, s, x_r, H_r, x_ext, SIGMA, HA, 1.0)
        # exact path: integrate each increment in the direction of motion
        step = x[k] - x[k - 1]
        s_true = 1.0 if step > 0 else (-1.0 if step < 0 else s_true)
        H_true = dahl_flow(H_true, step, s_true, SIGMA, HA, 1.0)
        assert H == pytest.approx(H_true, abs=2e-3 * HA)


def test_late_detected_reversal_still_turns_at_the_extreme():
    """The deadband detects a reversal late; the turnaround is placed at the extreme."""
    s, x_r, H_r, x_ext, H = 1.0, 0.0, 0.0, 0.0, 0.0
    for x in (1e-6, 2e-6, 3e-6):
        s, x_r, H_r, x_ext, H = dahl_update(x, 1.0, s, x_r, H_r, x_ext, SIGMA, HA, 1.0)
    H_peak = H
    s, x_r, H_r, x_ext, H = dahl_update(2.9e-6, 1.0, s, x_r, H_r, x_ext, SIGMA, HA, 1.0)  # not yet detected
    s, x_r, H_r, x_ext, H = dahl_update(2.5e-6, -1.0, s, x_r, H_r, x_ext, SIGMA, HA, 1.0)  # detected here
    assert (x_r, H_r) == (3e-6, pytest.approx(H_peak, rel=1e-14))
    assert H == pytest.approx(dahl_flow(H_peak, -0.5e-6, -1.0, SIGMA, HA, 1.0), rel=1e-14)


@pytest.mark.parametrize("alpha", [1 - 1e-9, 1 - 1e-5, 1 + 1e-5, 1 + 1e-9])
def test_closed_form_is_continuous_at_alpha_one(alpha):
    """Near alpha = 1 the alpha != 1 form must tend to the exponential, not cancel away
    (a naive y**(1-alpha) round trip loses every digit at alpha = 1 - 1e-9)."""
    for s, H_r in [(1.0, -0.8e-3), (-1.0, 0.5e-3), (1.0, 0.99e-3)]:
        for dx in np.linspace(-2e-6, 1e-5, 25):
            H_a = dahl_flow(H_r, s * dx, s, SIGMA, HA, alpha)
            H_1 = dahl_flow(H_r, s * dx, s, SIGMA, HA, 1.0)
            assert abs(H_a - H_1) <= 10 * abs(alpha - 1) * HA + 1e-15

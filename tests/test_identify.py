"""Least squares of eq. (4-5): both derivative paths recover known parameters from
synthetic data (noise-free: to numerical precision / discretisation error; noisy: within
stated tolerances), the EMPS published estimates are reproduced, and data that cannot
determine a term are refused with a message naming it."""
import numpy as np
import pytest

from servo.identify import (
    IdentificationError, RobustSettings, identify, least_squares, paper_regression, parse_terms,
    robust_regression,
)  # fmt: skip
from servo.io.recording import Recording, load_recording
from tests.helpers import EMPS_MAT

TRUE = {"J": 1.0e-3, "B": 2.0e-3, "Fc": 1.0e-3, "K": 0.1, "h0": 2.0e-3}


def model_force(p, a, v, x):
    """Eq. (3): the force of parameters ``p`` on motion ``(a, v, x)``."""
    return p["J"] * a + p["B"] * v + p["Fc"] * np.sign(v) + p["K"] * x + p["h0"]


def smooth_motion(n, dt, amp=1e-3):
    """An analytic motion (two sines, velocity reversing) and its exact derivatives."""
    t = np.arange(n) * dt
    w1, w2 = 2 * np.pi * 3.0, 2 * np.pi * 7.3
    x = amp * (np.sin(w1 * t) + 0.4 * np.sin(w2 * t + 0.3)) + 0.2 * amp
    v = amp * (w1 * np.cos(w1 * t) + 0.4 * w2 * np.cos(w2 * t + 0.3))
    a = -amp * (w1**2 * np.sin(w1 * t) + 0.4 * w2**2 * np.sin(w2 * t + 0.3))
    return t, x, v, a


def rel_errors(fit, true):
    return {k: abs(fit[k] - true[k]) / abs(true[k]) for k in fit.terms}


def test_paper_path_noise_free_is_exact():
    """Rows built as the paper's path builds them: the LS of eq. (5) returns the
    parameters to rounding error, with zero residual."""
    dt = 2e-5
    t, x, v, _ = smooth_motion(20000, dt)
    a_k = np.diff(v) / dt
    u = np.empty_like(t)
    u[:-1] = model_force(TRUE, a_k, 0.5 * (v[1:] + v[:-1]), 0.5 * (x[1:] + x[:-1]))
    u[-1] = 0.0  # never used: the last sample starts no interval
    fit = least_squares(paper_regression(t, x, u, v, dt))
    assert max(rel_errors(fit, TRUE).values()) < 1e-9
    assert fit.rel_error_pct < 1e-8


def test_paper_path_on_a_zero_order_hold_double_integrator():
    """A mass with Coulomb friction and an offset, simulated exactly under a zero-order
    hold: the backward difference of the velocity is exact there, so J, Fc, h0 are
    recovered exactly (rows where the velocity reverses inside an interval excepted)."""
    dt, n = 1e-4, 20000
    p = {"J": 2e-3, "Fc": 3e-3, "h0": -1e-3}
    u = 0.05 * np.sign(np.sin(2 * np.pi * 10 * np.arange(n) * dt + 0.2)) + 0.01 * np.sin(2 * np.pi * 37 * np.arange(n) * dt)
    x, v = np.zeros(n), np.zeros(n)
    v[0] = -0.5 * 0.05 / p["J"] * 0.025  # centred velocity swing: reversals both ways
    for k in range(n - 1):
        acc = (u[k] - p["Fc"] * np.sign(v[k]) - p["h0"]) / p["J"]
        v[k + 1] = v[k] + acc * dt
        x[k + 1] = x[k] + v[k] * dt + 0.5 * acc * dt * dt
    reg = paper_regression(np.arange(n) * dt, x, u, v, dt, terms=("J", "Fc", "h0"))
    fit = least_squares(reg)
    assert max(rel_errors(fit, p).values()) < 5e-3  # only the ~20 reversal intervals per second are off


def test_robust_path_noise_free_recovers_the_parameters():
    dt = 1e-3
    t, x, v, a = smooth_motion(20000, dt)
    u = model_force(TRUE, a, v, x)
    fit = least_squares(robust_regression(t, x, u, dt))
    err = rel_errors(fit, TRUE)
    assert max(err.values()) < 2e-3, err  # central differences and filtering: discretisation only
    assert fit.rel_error_pct < 0.5


def test_robust_path_noisy_within_tolerance():
    """Quantised position (0.5 um steps) and 2 % force noise: J, B, Fc within 3 %, K and h0
    within 5 %, and every error within 4 reported standard deviations."""
    rng = np.random.default_rng(7)
    dt = 1e-3
    t, x, v, a = smooth_motion(40000, dt)
    u = model_force(TRUE, a, v, x)
    u_noisy = u + 0.02 * np.std(u) * rng.standard_normal(u.size)
    x_q = np.round(x / 0.5e-6) * 0.5e-6
    fit = least_squares(robust_regression(t, x_q, u_noisy, dt))
    err = rel_errors(fit, TRUE)
    assert all(err[k] < 0.03 for k in ("J", "B", "Fc")), err
    assert all(err[k] < 0.05 for k in ("K", "h0")), err
    for k in fit.terms:
        assert abs(fit[k] - TRUE[k]) < 4 * fit.std[fit.terms.index(k)] + 1e-3 * abs(TRUE[k]), k


def test_force_lag_realigns_a_delayed_force():
    """A force that acts 3 samples late: ignored, B is biased; declared, recovered."""
    dt = 1e-3
    t, x, v, a = smooth_motion(20000, dt)
    u_true = model_force(TRUE, a, v, x)  # the force acting at t
    u_rec = np.interp(t + 3 * dt, t, u_true)  # recorded 3 samples early: it acts 3 samples late
    biased = least_squares(robust_regression(t, x, u_rec, dt))
    fit = least_squares(robust_regression(t, x, u_rec, dt, force_lag_s=3 * dt))
    assert rel_errors(biased, TRUE)["B"] > 0.05
    assert max(rel_errors(fit, TRUE).values()) < 5e-3


def test_switching_terms_off_and_unknown_terms():
    assert parse_terms(off="K") == ("J", "B", "Fc", "h0")
    assert parse_terms("h0,J") == ("J", "h0")
    with pytest.raises(IdentificationError, match="unknown term 'M'"):
        parse_terms("M,B")
    dt = 1e-3
    t, x, v, a = smooth_motion(20000, dt)
    p = dict(TRUE, K=0.0)
    fit = least_squares(robust_regression(t, x, model_force(p, a, v, x), dt, terms=parse_terms(off="K")))
    assert fit.terms == ("J", "B", "Fc", "h0")
    assert max(rel_errors(fit, p).values()) < 2e-3


def test_unidentifiable_data_are_refused_with_the_reason():
    dt = 1e-3
    t = np.arange(5000) * dt
    # one direction only: Fc*sgn(v) is the offset h0 in disguise
    x = 1e-3 * t**2
    u = model_force(TRUE, np.full_like(t, 2e-3), 2e-3 * t, x)
    with pytest.raises(IdentificationError, match="Fc is not identifiable: the velocity hardly ever reverses"):
        least_squares(robust_regression(t, x, u, dt))
    # the arm never moves
    with pytest.raises(IdentificationError, match="nothing excited"):
        least_squares(robust_regression(t, np.full_like(t, 1e-3), np.full_like(t, 2e-3), dt))
    # K*x and h0 cannot be told apart when the position barely changes around an offset
    _, xs, vs, as_ = smooth_motion(5000, dt, amp=1e-9)
    xs = xs + 1.0  # a 1 m offset with nanometres of motion
    with pytest.raises(IdentificationError, match="rank deficient.*K.*h0"):
        least_squares(robust_regression(t, xs, model_force(TRUE, as_, vs, xs), dt, terms=("K", "h0", "B")))
    with pytest.raises(IdentificationError, match="too short"):
        robust_regression(t[:100], x[:100], u[:100], dt)


def test_paper_path_needs_velocity():
    dt = 1e-3
    t, x, v, a = smooth_motion(2000, dt)
    rec = Recording(t, model_force(TRUE, a, v, x), x)
    with pytest.raises(IdentificationError, match="needs a measured velocity"):
        identify(rec, path="paper")


PUBLISHED = {"J": 95.1089, "B": 203.5034, "Fc": 20.3935, "h0": -3.1648}


def test_emps_reproduces_the_published_estimates():
    """EMPS (Janot et al. 2019): M, Fv, Fc, offset and the relative error 4.0834 % within
    0.5 %, with the reference method's settings (the defaults but no trimming at the end)."""
    rec = load_recording(EMPS_MAT, columns={"u": "vir", "x": "qm"}, scale={"u": "gtau"})
    res = identify(rec, path="robust", terms=parse_terms(off="K"), settings=RobustSettings.emps_reference())
    fit = res.fit
    for k, ref in PUBLISHED.items():
        assert abs(fit[k] - ref) / abs(ref) < 0.005, (k, fit[k], ref)
    assert abs(fit.rel_error_pct - 4.0834) / 4.0834 < 0.005
    assert abs(fit.cond - 25.99) < 0.05
    assert res.regression.n_rows == 2480

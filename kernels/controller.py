"""The controller tick: Dahl update -> compensator -> PI holding loop -> limits.

One call per sample.  State and parameters are one-element record arrays
(:data:`CTRL_STATE`, :data:`CTRL_PARAMS`) so that the call allocates nothing.
"""
import math

import numpy as np
from numba import float64, from_dtype, njit, void

from kernels.compensator import SLOW, compensate, direction, regime_switch, velocity_estimate
from kernels.dahl import dahl_update
from kernels.holding import holding_pi, holding_pi_bumpless

CTRL_PARAMS = np.dtype(
    [
        ("dt", "f8"),  # sample period, s
        ("kp", "f8"),  # holding loop proportional gain, A/m
        ("ki", "f8"),  # holding loop integral gain, A/(m*s)
        ("kd", "f8"),  # holding loop rate feedback, A*s/m
        ("b", "f8"),  # holding loop setpoint weight of the proportional term
        ("u_n_max", "f8"),  # holding loop output limit, A
        ("u_max", "f8"),  # total command limit, A
        ("use_measured_v", "f8"),  # 1: use the drive's velocity when it has one
        ("v_alpha", "f8"),  # velocity estimator pole, exp(-2*pi*f_c*dt)
        ("v_deadband", "f8"),  # direction deadband, m/s
        ("comp_on", "f8"),  # 1: compensator on
        ("B", "f8"),  # compensator viscous friction, A*s/m
        ("Fc", "f8"),  # compensator Coulomb friction, A
        ("K", "f8"),  # compensator bias stiffness, A/m
        ("h0", "f8"),  # compensator bias offset, A
        ("sigma", "f8"),  # compensator Dahl slope, A/m
        ("Ha", "f8"),  # compensator Dahl asymptote, A
        ("alpha", "f8"),  # compensator Dahl exponent
        ("v_on", "f8"),  # SLOW -> FAST speed, m/s
        ("v_off", "f8"),  # FAST -> SLOW speed, m/s
        ("xi_on", "f8"),  # SLOW -> FAST distance since the latest turnaround, m
    ]
)
CTRL_STATE = np.dtype(
    [
        ("r_base", "f8"),  # holding position: where the arm was when the loop took over, m
        ("x_prev", "f8"),  # previous measured position, m
        ("v", "f8"),  # velocity used this sample (measured or estimated), m/s
        ("s", "f8"),  # direction of motion, +1/-1
        ("x_r", "f8"),  # latest turnaround position, m
        ("H_r", "f8"),  # Dahl estimate at the latest turnaround, A
        ("x_ext", "f8"),  # furthest position since the turnaround, m
        ("H_dahl", "f8"),  # Dahl estimate, A
        ("regime", "f8"),  # 0 SLOW (Dahl), 1 FAST (eq. 3)
        ("integ", "f8"),  # holding loop integrator, A
        ("e", "f8"),  # position error, m
        ("u", "f8"),  # total command, A
        ("u_n", "f8"),  # nominal input (holding loop + excitation), A
        ("u_c", "f8"),  # compensation current, A
    ]
)
ctrl_params_t = from_dtype(CTRL_PARAMS)[::1]
ctrl_state_t = from_dtype(CTRL_STATE)[::1]
# helpers take the records themselves (by reference): no reference counting per call
params_rec_t = from_dtype(CTRL_PARAMS)
state_rec_t = from_dtype(CTRL_STATE)


@njit(float64(state_rec_t, params_rec_t, float64), cache=True)
def _compensation(c, p, x):
    if p.comp_on == 0.0:
        return 0.0
    return compensate(int(c.regime), x, c.v, c.s, c.H_dahl, p.B, p.Fc, p.K, p.h0)


@njit(void(ctrl_state_t, ctrl_params_t, float64, float64, float64), cache=True)
def controller_start(cs, cp, x, v_meas, u_now):
    """Take over the arm bumplessly: hold the current position ``x`` (m), with the first
    output equal to ``u_now`` (A), the current the drive applies at hand-over."""
    c = cs[0]
    p = cp[0]
    v = v_meas if (p.use_measured_v != 0.0 and not math.isnan(v_meas)) else 0.0
    c.r_base = x
    c.x_prev = x
    c.v = v
    c.s = 1.0
    c.x_r = x
    c.H_r = 0.0  # the pivot's hysteresis state is unknown: start at the loop's centre
    c.x_ext = x
    c.H_dahl = 0.0
    c.regime = float(SLOW)
    c.e = 0.0
    u_c = _compensation(c, p, x)
    c.integ = holding_pi_bumpless(u_now - u_c, 0.0, v, p.kp, p.kd)
    c.u_c = u_c
    c.u_n = u_now - u_c
    c.u = u_now


@njit(float64(ctrl_state_t, ctrl_params_t, float64, float64, float64, float64), cache=True)
def controller_tick(cs, cp, x, v_meas, r, u_exc):
    """One sample: measured position ``x`` (m) and velocity ``v_meas`` (m/s, NaN if not
    measured), reference ``r`` (m, relative to the holding position), excitation ``u_exc``
    (A, added to the nominal input).  Returns the current command ``u`` (A)."""
    c = cs[0]
    p = cp[0]
    if p.use_measured_v != 0.0 and not math.isnan(v_meas):
        v = v_meas
    else:
        v = velocity_estimate(c.v, x, c.x_prev, p.dt, p.v_alpha)
    c.v = v
    c.x_prev = x

    s_new = direction(c.s, v, p.v_deadband)
    turned = 1.0 if s_new != c.s else 0.0
    c.s, c.x_r, c.H_r, c.x_ext, c.H_dahl = dahl_update(
        x, s_new, c.s, c.x_r, c.H_r, c.x_ext, p.sigma, p.Ha, p.alpha
    )  # eq. (6-7)
    c.regime = float(
        regime_switch(int(c.regime), v, c.s * (x - c.x_r), turned, p.v_on, p.v_off, p.xi_on)
    )
    u_c = _compensation(c, p, x)  # eq. (9)

    # the holding loop gets whatever room the compensator leaves under the current limit
    lo = max(-p.u_n_max, -p.u_max - u_c)
    hi = min(p.u_n_max, p.u_max - u_c)
    e = (c.r_base + r) - x
    e_p = (c.r_base + p.b * r) - x
    u_n, c.integ = holding_pi(e, e_p, v, c.integ, u_exc, p.kp, p.ki, p.kd, p.dt, lo, hi)
    u = u_n + u_c  # eq. (8)
    u = min(max(u, -p.u_max), p.u_max)
    c.e = e
    c.u_n = u_n
    c.u_c = u_c
    c.u = u
    return u

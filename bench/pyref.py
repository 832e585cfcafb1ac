"""The pure-Python reference: the controller tick of ``kernels/`` in plain Python floats
and :mod:`math`, same operations in the same order (so the same numbers, checked by
``bench/test_reference.py``).  It measures what compiling the kernels buys: the
Python/Numba ratio of the benchmarks.

State and parameters are plain objects whose attributes are the fields of the records
(:data:`~kernels.stage.STAGE_STATE`, :data:`~kernels.stage.STAGE_PARAMS`, the PI kind's
``STATE`` and ``PARAMS``; SI units, currents in A).
"""
from __future__ import annotations

import math

import numpy as np

SLOW, FAST = 0, 1


class Record:
    """Attributes named after a record dtype's fields, as Python floats."""

    def __init__(self, rec: np.ndarray):
        for name in rec.dtype.names:
            v = rec[0][name]
            setattr(self, name, v.copy() if np.ndim(v) else float(v))  # nested arrays stay arrays

    def to_array(self, like: np.ndarray) -> np.ndarray:
        out = np.zeros_like(like)
        for name in like.dtype.names:
            out[0][name] = getattr(self, name)
        return out


def dahl_flow(H, dx, s, sigma, Ha, alpha):
    y0 = 1.0 - s * H / Ha
    if y0 < 0.0:
        y0 = 0.0
    elif y0 > 2.0:
        y0 = 2.0
    xi = s * dx
    if alpha == 1.0:
        y = y0 * math.exp(-sigma * xi / Ha)
    else:
        e = 1.0 - alpha
        if y0 == 0.0:
            if e < 0.0:
                y = 0.0
            else:
                z = -e * sigma * xi / Ha
                y = z ** (1.0 / e) if z > 0.0 else 0.0
        else:
            w = e * sigma * xi / (Ha * y0**e)
            if w >= 1.0:
                y = 0.0 if e > 0.0 else 2.0
            else:
                y = y0 * math.exp(math.log1p(-w) / e)
    if y > 2.0:
        y = 2.0
    return s * Ha * (1.0 - y)


def dahl_update(x, s_new, s, x_r, H_r, x_ext, sigma, Ha, alpha):
    if s_new != s:
        H_r = dahl_flow(H_r, x_ext - x_r, s, sigma, Ha, alpha)
        x_r = x_ext
        s = s_new
        x_ext = x
    if s * (x - x_ext) > 0.0:
        x_ext = x
    H = dahl_flow(H_r, x - x_r, s, sigma, Ha, alpha)
    return s, x_r, H_r, x_ext, H


def velocity_estimate(v_prev, x, x_prev, dt, a):
    return a * v_prev + (1.0 - a) * (x - x_prev) / dt


def direction(s, v, deadband):
    if v > deadband:
        return 1.0
    if v < -deadband:
        return -1.0
    return s


def regime_switch(regime, v, xi, s_changed, v_on, v_off, xi_on):
    if regime == SLOW:
        if abs(v) >= v_on and xi >= xi_on:
            return FAST
        return SLOW
    if abs(v) < v_off or s_changed != 0.0:
        return SLOW
    return FAST


def compensate(regime, x, v, s, H_dahl, B, Fc, K, h0):
    bias = K * x + h0
    if regime == FAST:
        return B * v + Fc * s + bias
    return B * v + H_dahl + bias


def holding_pi(e, e_p, v, integ, u_ff, kp, ki, kd, dt, lo, hi):
    u = kp * e_p + integ - kd * v + u_ff
    winding = False
    if u > hi:
        u = hi
        winding = e > 0.0
    elif u < lo:
        u = lo
        winding = e < 0.0
    if not winding:
        integ += ki * dt * e
    return u, integ


def _compensation(c, p, x):
    if p.comp_on == 0.0:
        return 0.0
    return compensate(int(c.regime), x, c.v, c.s, c.H_dahl, p.B, p.Fc, p.K, p.h0)


def controller_tick(c, p, ci, cp, x, v_meas, r, u_exc):
    """One sample of the PI kind on its stage (:mod:`kernels.compose`); ``c``/``p`` the
    stage's state and parameters, ``ci``/``cp`` the PI's, all :class:`Record` objects.
    Returns the current command (A)."""
    if p.use_measured_v != 0.0 and not math.isnan(v_meas):
        v = v_meas
    else:
        v = velocity_estimate(c.v, x, c.x_prev, p.dt, p.v_alpha)
    c.v = v
    c.x_prev = x

    s_new = direction(c.s, v, p.v_deadband)
    turned = 1.0 if s_new != c.s else 0.0
    c.s, c.x_r, c.H_r, c.x_ext, c.H_dahl = dahl_update(x, s_new, c.s, c.x_r, c.H_r, c.x_ext, p.sigma, p.Ha, p.alpha)
    c.regime = float(regime_switch(int(c.regime), v, c.s * (x - c.x_r), turned, p.v_on, p.v_off, p.xi_on))
    u_c = _compensation(c, p, x)

    lo = max(-cp.u_n_max, -p.u_max - u_c)
    hi = min(cp.u_n_max, p.u_max - u_c)
    e = (c.r_base + r) - x
    e_p = (c.r_base + cp.b * r) - x
    u_n, ci.integ = holding_pi(e, e_p, v, ci.integ, u_exc, cp.kp, cp.ki, cp.kd, cp.dt, lo, hi)
    u = u_n + u_c
    u = min(max(u, -p.u_max), p.u_max)
    c.e = e
    c.u_n = u_n
    c.u_c = u_c
    c.u = u
    return u


def loop_controller_tick(n, xin, recs):
    """:func:`bench.loops.loop_controller_tick` in Python: rows ``(x, v_meas, r, u_exc)``
    of ``xin`` (a list of tuples of floats, length a power of two); ``recs`` the four
    :class:`Record` objects of :func:`controller_tick`."""
    mask = len(xin) - 1
    acc = 0.0
    tick = controller_tick
    for k in range(n):
        x, v, r, u_exc = xin[k & mask]
        acc += tick(*recs, x, v, r, u_exc)
    return acc

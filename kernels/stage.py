"""The stage every controller sits on: motion signals, the paper's compensator, the limit.

A controller kind (:mod:`servo.controllers`) computes the nominal input ``u_n`` from the
position error; this stage wraps it, the same for every kind::

    v, s, H_hat, regime  <- x, v_meas       velocity, direction, Dahl update (eq. 6-7)
    u_c = B*v + Fc*sgn(v) + H_hat           eq. (9), 0 when the compensator is off
    [lo, hi] = [-u_max - u_c, u_max - u_c]  the room left for u_n under the current limit
    u_n = controller(x, v, r, u_exc, lo, hi)
    u = clip(u_n + u_c, -u_max, u_max)      eq. (8)

(``u_n + u_c`` divided by ``kf(x)`` and through the inverse dead zone when those terms
are on)

so that with exact estimates the plant any controller sees is ``J*x'' = u_n`` (eq. 10).
The reference ``r`` (m) is relative to the *holding position* ``r_base``: where the arm
was when the loop took over.  State and parameters are one-element record arrays
(:data:`STAGE_STATE`, :data:`STAGE_PARAMS`) so that a call allocates nothing; the kernels
take the records themselves (``ss[0]``).
"""
import math

import numpy as np
from numba import float64, from_dtype
from numba.types import UniTuple

from kernels._cache import kernel
from kernels.cancel import (
    MAX_HARMONICS, coulomb_stribeck, cubic_spring, dead_zone_inverse, force_constant, periodic, viscous_asymmetry,
)
from kernels.compensator import FAST, SLOW, compensate, direction, regime_switch, velocity_estimate
from kernels.dahl import dahl_update

STAGE_PARAMS = np.dtype(
    [
        ("dt", "f8"),  # sample period, s
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
        # terms beyond eq. (9) (kernels/cancel.py), applied only when ``extras`` is 1
        ("extras", "f8"),  # 1: any of the terms below is on
        ("b_asym", "f8"),  # viscous asymmetry: B(s) = B*(1 + s*b_asym)
        ("coul_c", "f8"),  # Coulomb friction beyond the Dahl element, A
        ("coul_s", "f8"),  # its static (Stribeck peak) level, A
        ("coul_vs", "f8"),  # Stribeck velocity, m/s
        ("coul_asym", "f8"),  # its asymmetry: F(s) = F*(1 + s*coul_asym)
        ("n_per", "f8"),  # harmonics of the periodic term in use
        ("per_period", "f8"),  # its period in position, m
        ("per_sin", "f8", (MAX_HARMONICS,)),  # A_i*cos(phi_i): coefficients of sin(i*th), A
        ("per_cos", "f8", (MAX_HARMONICS,)),  # A_i*sin(phi_i): coefficients of cos(i*th), A
        ("kf_on", "f8"),  # 1: divide the command by kf(x)
        ("kf1", "f8"),  # force-constant change at +stroke, linear
        ("kf2", "f8"),  # force-constant change at +-stroke, quadratic
        ("kf_stroke", "f8"),  # the stroke those refer to, m
        # authority: what a wrong model can do is bounded (docs/compensate.md)
        ("uc_max", "f8"),  # |u_c| <= uc_max, A (inf: eq. 9 unbounded, as the paper writes it)
        ("kf_lo", "f8"),  # the divisor kf(x) is held within [kf_lo, kf_hi]
        ("kf_hi", "f8"),
        ("k3", "f8"),  # cubic spring k3*x^3 cancelled (an extra, within uc_max), A/m^3
        ("dz_w", "f8"),  # inverse dead zone: sgn(u)*dz_w added to the command, A (its authority applied; 0: off)
    ]
)
STAGE_STATE = np.dtype(
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
        ("e", "f8"),  # position error (r_base + r) - x, m
        ("u", "f8"),  # total command, A
        ("u_n", "f8"),  # nominal input (the controller's output), A
        ("u_c", "f8"),  # compensation current, A
    ]
)
stage_params_t = from_dtype(STAGE_PARAMS)[::1]
stage_state_t = from_dtype(STAGE_STATE)[::1]
# The kernels below take the records themselves (``ss[0]``), which numba passes by
# reference: no reference counting per call, as an array argument would cost.
stage_params_rec_t = from_dtype(STAGE_PARAMS)
stage_state_rec_t = from_dtype(STAGE_STATE)


@kernel(float64(stage_state_rec_t, stage_params_rec_t, float64), helper=True)
def _extras(c, p, x):
    """The terms beyond eq. (9) (:mod:`kernels.cancel`), A.  The Coulomb term (with its
    Stribeck rise and asymmetry) acts while the arm slides: in the large-motion regime
    (eq. 3), or anywhere at the speed that regime keeps (``v_off``).  Slower, near a
    turnaround, where a sticking friction holds rather than slides, a sign(v) term would
    flip at every micro-reversal of a small step (measured: a limit cycle on a 0.3 um
    step): it rests there."""
    f = 0.0
    if p.b_asym != 0.0:
        f += viscous_asymmetry(c.v, c.s, p.B, p.b_asym)
    if (p.coul_c != 0.0 or p.coul_s != 0.0) and (c.regime == FAST or abs(c.v) >= p.v_off):  # sliding
        f += coulomb_stribeck(c.v, c.s, p.coul_c, p.coul_s, p.coul_vs, p.coul_asym)
    if p.n_per > 0.0:
        f += periodic(x, p.per_sin, p.per_cos, int(p.n_per), p.per_period)
    if p.k3 != 0.0:
        f += cubic_spring(x, p.k3)
    return f


@kernel(float64(stage_state_rec_t, stage_params_rec_t, float64), helper=True)
def _compensation(c, p, x):
    if p.comp_on == 0.0:
        return 0.0
    u_c = compensate(int(c.regime), x, c.v, c.s, c.H_dahl, p.B, p.Fc, p.K, p.h0)
    if p.extras != 0.0:
        u_c += _extras(c, p, x)
    return min(max(u_c, -p.uc_max), p.uc_max)  # the authority: a bounded input to the loop


@kernel(float64(stage_params_rec_t, float64), helper=True)
def _kf(p, x):
    """The divisor ``kf(x)`` of the force-constant term, held within its authority."""
    return min(max(force_constant(x, p.kf1, p.kf2, p.kf_stroke), p.kf_lo), p.kf_hi)


@kernel(float64(stage_state_rec_t, stage_params_rec_t, float64, float64, float64), helper=True)
def stage_start(c, p, x, v_meas, u_now):
    """Take over at position ``x`` (m), velocity ``v_meas`` (m/s, NaN if not measured) with
    ``u_now`` (A) applied: hold ``x``, reset the signals (the pivot's hysteresis state is
    unknown: the Dahl estimate starts at the loop's centre), and return the nominal input
    ``u_now - u_c`` (A) the controller must take over from for a bumpless start."""
    v = v_meas if (p.use_measured_v != 0.0 and not math.isnan(v_meas)) else 0.0
    c.r_base = x
    c.x_prev = x
    c.v = v
    c.s = 1.0
    c.x_r = x
    c.H_r = 0.0
    c.x_ext = x
    c.H_dahl = 0.0
    c.regime = float(SLOW)
    c.e = 0.0
    u_c = _compensation(c, p, x)
    force = u_now  # what u_n + u_c must make for the first command to be u_now
    if p.dz_w > 0.0 and p.comp_on != 0.0:  # what the command makes through the dead zone
        force = u_now - min(max(u_now, -p.dz_w), p.dz_w)
    if p.kf_on != 0.0 and p.comp_on != 0.0:
        force = force * _kf(p, x)
    c.u_c = u_c
    c.u_n = force - u_c
    c.u = u_now
    return force - u_c


@kernel(float64(stage_state_rec_t, stage_params_rec_t, float64, float64), helper=True)
def stage_update(c, p, x, v_meas):
    """The signals of one sample at measured position ``x`` (m) and velocity ``v_meas``
    (m/s, NaN if not measured): velocity, direction, Dahl estimate (eq. 6-7), regime;
    returns the compensation current ``u_c`` (A, eq. 9)."""
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
    return _compensation(c, p, x)  # eq. (9)


@kernel(UniTuple(float64, 2)(stage_params_rec_t, float64, float64), helper=True)
def stage_room(p, u_c, x):
    """``(lo, hi)`` (A): the range of ``u_n`` that keeps the command within the limit
    (``u_n + u_c``, divided by ``kf(x)`` when the force constant is cancelled, widened
    by the inverse dead zone's ``dz_w`` when that is on)."""
    u_max = p.u_max
    if p.dz_w > 0.0 and p.comp_on != 0.0:
        u_max = max(p.u_max - p.dz_w, 0.0)
    if p.kf_on != 0.0 and p.comp_on != 0.0:
        m = u_max * _kf(p, x)
        return -m - u_c, m - u_c
    return -u_max - u_c, u_max - u_c


@kernel(float64(stage_state_rec_t, stage_params_rec_t, float64, float64, float64, float64), helper=True)
def stage_output(c, p, x, r, u_n, u_c):
    """The command ``u = clip(u_n + u_c)`` (A, eq. 8) for the controller's ``u_n`` (A);
    records the error ``(r_base + r) - x`` (m) and the three currents."""
    u = u_n + u_c  # eq. (8)
    if p.kf_on != 0.0 and p.comp_on != 0.0:  # the force is kf(x)*u: command what makes u_n + u_c of it
        u = u / _kf(p, x)
    if p.dz_w > 0.0 and p.comp_on != 0.0:  # the force is dz(u): command what makes u of it
        u = dead_zone_inverse(u, p.dz_w)
    u = min(max(u, -p.u_max), p.u_max)
    c.e = (c.r_base + r) - x
    c.u_n = u_n
    c.u_c = u_c
    c.u = u
    return u

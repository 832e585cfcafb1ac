"""The simulated VCM drive: one sample of the plant of docs/model.md (paper eq. 1).

Forces are normalised to amperes (force constant 1 at the stroke centre)::

    J*x'' = kf(x)*u + d - B(s)*x' - C(x', s)*s - H - K*x - k3*x^3 - h0 - cog(x)

* ``u`` the applied current (A): the command, clipped to ``+-u_max``, through the dead
  zone and delayed by ``delay_whole*dt + delay_frac`` seconds; ``d`` a disturbance force (A).
* ``H`` the pivot's Dahl hysteresis (eq. 6, its sliding level ``Ha`` is the pivot friction),
  integrated *exactly in position* inside each sub-step (:func:`kernels.dahl.dahl_flow`
  from the sub-step's start), so the element stays exact at any speed where its
  differential form in time would be stiff.
* ``C`` an optional Coulomb/Stribeck friction with static friction ``Fs`` (breakaway) and
  ``Fc`` (sliding), direction-asymmetric by ``fc_asym``; ``B(s) = B*(1 + s*b_asym)``.
* ``kf(x) = 1 + kf1*(x/stroke) + kf2*(x/stroke)**2`` force-constant variation; ``cog(x)``
  a periodic (cogging) force; ``k3*x^3`` a cubic spring (hardening ``k3 > 0``, softening
  ``k3 < 0``); hard stops at ``+-stroke``.
* An input dead zone of half-width ``dz_width`` after the clipping: the arm gets
  ``sgn(u)*max(|u| - dz_width, 0)`` of the clipped command, applied to each delayed
  piece (the input delay buffer holds the clipped commands: a memoryless map commutes
  with the delay, and what entered the amplifier stays the command).
* Flexible modes ``q_i'' + 2*zeta_i*w_i*q_i' + w_i**2*q_i = u/J`` add ``g_i*q_i`` to the
  measured position; they are linear and advanced with their exact zero-order-hold
  discretisation (matrices from :mod:`servo.runtime.simplant`), once per constant-input interval.

Sticking: at rest (``v == 0``) the arm stays put while the net force is within the
breakaway level (exactly zero motion, no creep); when the velocity reverses inside a
sub-step and the net force is within breakaway, it sticks (``v = 0``).  With only the Dahl
element (the default drive) there is no discontinuity at ``v = 0`` at all: below ``Ha``
the pivot is a stiff spring and the arm comes to rest on it.

Within one sample the input is piecewise constant: ``u[k-m-1]`` for the first
``delay_frac`` seconds, then ``u[k-m]`` (``m = delay_whole``); each piece is integrated
with ``n_sub`` RK4 sub-steps.
"""
import math

import numpy as np
from numba import float64, from_dtype, void
from numba.types import UniTuple

from kernels._cache import kernel
from kernels.dahl import dahl_flow
from kernels.delay import shift_in

PLANT_PARAMS = np.dtype(
    [
        ("J", "f8"),  # normalised inertia, A*s^2/m
        ("B", "f8"),  # viscous friction, A*s/m
        ("b_asym", "f8"),  # viscous asymmetry, B(s) = B*(1 + s*b_asym)
        ("Fc", "f8"),  # Coulomb (sliding) friction, A
        ("Fs", "f8"),  # static (breakaway) friction, A, >= Fc
        ("fc_asym", "f8"),  # Coulomb asymmetry, Fc(s) = Fc*(1 + s*fc_asym)
        ("vs", "f8"),  # Stribeck velocity, m/s
        ("sigma", "f8"),  # Dahl pre-sliding stiffness, A/m
        ("Ha", "f8"),  # Dahl asymptote (pivot sliding friction), A
        ("alpha", "f8"),  # Dahl shape exponent
        ("K", "f8"),  # bias stiffness, A/m
        ("h0", "f8"),  # bias offset, A
        ("cog_amp", "f8"),  # cogging force amplitude, A
        ("cog_period", "f8"),  # cogging period in position, m
        ("cog_phase", "f8"),  # cogging phase, rad
        ("kf1", "f8"),  # force-constant variation, linear (fraction at +stroke)
        ("kf2", "f8"),  # force-constant variation, quadratic (fraction at +-stroke)
        ("stroke", "f8"),  # hard stops at +-stroke, m
        ("u_max", "f8"),  # amplifier current limit, A
        ("dt", "f8"),  # sample period, s
        ("delay_frac", "f8"),  # fractional part of the input delay, s, in [0, dt)
        ("delay_whole", "f8"),  # whole samples of input delay
        ("n_sub", "f8"),  # RK4 sub-steps per constant-input interval
        ("noise_x", "f8"),  # position sensor noise, m (std)
        ("noise_v", "f8"),  # velocity sensor noise, m/s (std)
        ("quantum", "f8"),  # position quantisation step, m (0: none)
        ("has_velocity", "f8"),  # 1: the drive measures velocity (LDV), 0: not
        ("sensor_a", "f8"),  # first-order position sensor low-pass, a = 1 - exp(-2*pi*fc*dt) (0: none)
        ("dz_width", "f8"),  # input dead zone half-width, A (0: none)
        ("k3", "f8"),  # cubic spring k3*x^3, A/m^3 (> 0 hardening, < 0 softening; 0: none)
        ("backlash", "f8"),  # half-gap of the play between motor and load (the sensor reads the load), m (0: none)
    ]
)
#: the plant's states; the measured-side positions are named ``y_*`` (they start at the
#: measured position at rest, :func:`servo.runtime.simplant.build_plant`)
PLANT_STATE = np.dtype(
    [
        ("x", "f8"),  # rigid-body position, m
        ("v", "f8"),  # rigid-body velocity, m/s
        ("H", "f8"),  # Dahl hysteresis force, A
        ("y_lp", "f8"),  # the position sensor low-pass's output (noiseless), m
        ("y_load", "f8"),  # the load's position behind the backlash (noiseless), m
    ]
)
plant_params_t = from_dtype(PLANT_PARAMS)[::1]
plant_state_t = from_dtype(PLANT_STATE)[::1]
# The public kernels take the one-element record arrays; the helpers they call take the
# records themselves (passed by reference), which costs no reference counting per call
# (a quarter of plant_step's time when they took the arrays).
params_rec_t = from_dtype(PLANT_PARAMS)
state_rec_t = from_dtype(PLANT_STATE)


@kernel(float64(float64, params_rec_t), helper=True)
def force_constant(x, p):
    """Force constant relative to the stroke centre, ``kf(x)`` (dimensionless)."""
    r = x / p.stroke
    return 1.0 + p.kf1 * r + p.kf2 * r * r


@kernel(float64(float64, float64), helper=True)
def dead_zone(u, w):
    """The input dead zone of half-width ``w`` (A): ``sgn(u)*max(|u| - w, 0)`` (A)."""
    if u > w:
        return u - w
    if u < -w:
        return u + w
    return 0.0


@kernel(float64(float64, float64, float64, params_rec_t), helper=True)
def drive_force(x, u, d, p):
    """Every force on the arm except friction and hysteresis (A)."""
    f = force_constant(x, p) * u + d - p.K * x - p.h0
    if p.cog_amp != 0.0:
        f -= p.cog_amp * math.sin(2.0 * math.pi * x / p.cog_period + p.cog_phase)
    if p.k3 != 0.0:
        f -= p.k3 * x * x * x
    return f


@kernel(float64(float64, float64, params_rec_t), helper=True)
def sliding_friction(v, s, p):
    """Viscous plus Coulomb/Stribeck friction (A) while moving in direction ``s``."""
    f = p.B * (1.0 + s * p.b_asym) * v
    if p.Fs > 0.0:
        fc = p.Fc * (1.0 + s * p.fc_asym)
        fs = p.Fs * (1.0 + s * p.fc_asym)
        f += s * (fc + (fs - fc) * math.exp(-((v / p.vs) ** 2)))
    return f


@kernel(float64(float64, params_rec_t), helper=True)
def breakaway(s, p):
    """Static friction (A) to overcome to start moving in direction ``s``."""
    return p.Fs * (1.0 + s * p.fc_asym)


@kernel(
    float64(float64, float64, float64, float64, float64, float64, float64, params_rec_t),
    inline="always",
    helper=True,
)
def acceleration(x, v, s, x0, H0, u, d, p):
    """``x''`` (m/s^2) within a sub-step that started at ``(x0, H0)`` moving in ``s``."""
    H = dahl_flow(H0, x - x0, s, p.sigma, p.Ha, p.alpha)
    return (drive_force(x, u, d, p) - sliding_friction(v, s, p) - H) / p.J


# acceleration and rigid_substep are inlined (Numba's IR inlining; LLVM did not inline
# them): a sample runs 4 n_sub sub-steps of 4 accelerations each, and every call passed
# two records' fields and checked a status code.  The kernel alone went from 1.14x to
# 1.09x the C loop of the same arithmetic, with the same bits (2026-11-28).
@kernel(void(state_rec_t, params_rec_t, float64, float64, float64), inline="always", helper=True)
def rigid_substep(st, p, u, d, h):
    """Advance rigid body and Dahl state by ``h`` seconds under constant ``u``, ``d``."""
    x0 = st.x
    v0 = st.v
    H0 = st.H
    if v0 > 0.0:
        s = 1.0
    elif v0 < 0.0:
        s = -1.0
    else:
        f = drive_force(x0, u, d, p) - H0
        if f == 0.0:
            return
        s = 1.0 if f > 0.0 else -1.0
        if abs(f) <= breakaway(s, p):
            return  # stuck: static friction holds, not a nanometre of creep
    k1x = v0
    k1v = acceleration(x0, v0, s, x0, H0, u, d, p)
    k2x = v0 + 0.5 * h * k1v
    k2v = acceleration(x0 + 0.5 * h * k1x, k2x, s, x0, H0, u, d, p)
    k3x = v0 + 0.5 * h * k2v
    k3v = acceleration(x0 + 0.5 * h * k2x, k3x, s, x0, H0, u, d, p)
    k4x = v0 + h * k3v
    k4v = acceleration(x0 + h * k3x, k4x, s, x0, H0, u, d, p)
    x1 = x0 + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
    v1 = v0 + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    if x1 > p.stroke:
        x1 = p.stroke
        v1 = min(v1, 0.0)
    elif x1 < -p.stroke:
        x1 = -p.stroke
        v1 = max(v1, 0.0)
    H1 = dahl_flow(H0, x1 - x0, s, p.sigma, p.Ha, p.alpha)
    if s * v1 < 0.0 and p.Fs > 0.0:
        # the velocity reversed inside the sub-step: static friction may catch the arm
        f = drive_force(x1, u, d, p) - H1
        if abs(f) <= breakaway(1.0 if f > 0.0 else -1.0, p):
            v1 = 0.0
    st.x = x1
    st.v = v1
    st.H = H1


@kernel(void(float64[:, ::1], float64[:, :, ::1], float64, float64), inline="always", helper=True)
def modes_advance(q, mab, part, u):
    """Advance the flexible modes ``q[i] = (q_i, q_i')`` over one constant-input interval
    with their exact discretisation ``mab[i, part] = (a11, a12, a21, a22, b1, b2)``."""
    j = int(part)
    for i in range(q.shape[0]):
        q0 = q[i, 0]
        q1 = q[i, 1]
        q[i, 0] = mab[i, j, 0] * q0 + mab[i, j, 1] * q1 + mab[i, j, 4] * u
        q[i, 1] = mab[i, j, 2] * q0 + mab[i, j, 3] * q1 + mab[i, j, 5] * u


@kernel(void(state_rec_t, params_rec_t, float64, float64, float64), helper=True)
def rigid_advance(st, p, u, d, h):
    """``n_sub`` RK4 sub-steps covering ``h`` seconds."""
    n = int(p.n_sub)
    hs = h / n
    for _ in range(n):
        rigid_substep(st, p, u, d, hs)


@kernel(
    void(
        plant_state_t,
        plant_params_t,
        float64[:, ::1],
        float64[:, :, ::1],
        float64[::1],
        float64,
        float64,
    ),
)
def plant_step(ps, pp, q, mab, ubuf, u_cmd, d):
    """Advance the drive by one sample period under the current command ``u_cmd`` (A) and
    disturbance force ``d`` (A).  ``ubuf`` (length ``delay_whole + 2``) holds the past
    commands of the input delay; ``q``/``mab`` the flexible modes (see module doc)."""
    p = pp[0]
    st = ps[0]
    u = min(max(u_cmd, -p.u_max), p.u_max)
    shift_in(ubuf, u)
    m = int(p.delay_whole)
    u_late = ubuf[m]
    u_early = ubuf[m + 1]
    if p.dz_width > 0.0:  # the buffer holds the clipped commands, the arm gets them through the dead zone
        u_late = dead_zone(u_late, p.dz_width)
        u_early = dead_zone(u_early, p.dz_width)
    # The modes and the rigid body do not feed each other within a sample: the modes go
    # first, so that no call that may raise (rigid_advance's) lies between the arrays'
    # uses, and Numba prunes every reference count of q and mab (modes_advance is
    # inlined: a call handed the arrays kept three increments and decrements a sample).
    if p.delay_frac > 0.0:
        modes_advance(q, mab, 0.0, u_early)
    modes_advance(q, mab, 1.0, u_late)
    if p.delay_frac > 0.0:
        rigid_advance(st, p, u_early, d, p.delay_frac)
    rigid_advance(st, p, u_late, d, p.dt - p.delay_frac)


@kernel(
    UniTuple(float64, 2)(
        plant_state_t, plant_params_t, float64[:, ::1], float64[::1], float64, float64
    ),
)
def plant_measure(ps, pp, q, gain, nx, nv):
    """The sensor: ``(x_meas, v_meas)`` in m and m/s at the current instant.

    Position = rigid + ``sum(g_i*q_i)`` + ``noise_x*nx``, quantised to ``quantum``;
    velocity likewise with ``noise_v*nv``, or NaN when the drive measures no velocity.
    ``nx``, ``nv`` are standard-normal draws supplied by the caller (seeded upstream).

    With a backlash (``backlash`` > 0, the half-gap) the sensor reads the load, which
    follows the motor's position (rigid + modes) through a play, advanced here once per
    call: the load ``y_load`` stands while the motor moves inside the gap and is pushed
    along at the gap's edge, ``y_load = clip(y_load, y - backlash, y + backlash)``.
    With a sensor low-pass (``sensor_a`` > 0) the position before noise and quantisation
    is ``y_lp``, advanced here, once per call: ``y_lp += sensor_a*(rigid + modes - y_lp)``
    (call once per sample; the velocity is not filtered).  Without one nothing of the
    state is touched.
    """
    st = ps[0]
    p = pp[0]
    y = st.x
    yd = st.v
    for i in range(q.shape[0]):
        y += gain[i] * q[i, 0]
        yd += gain[i] * q[i, 1]
    if p.backlash > 0.0:
        if y > st.y_load + p.backlash:
            st.y_load = y - p.backlash
        elif y < st.y_load - p.backlash:
            st.y_load = y + p.backlash
        y = st.y_load
    if p.sensor_a > 0.0:
        st.y_lp += p.sensor_a * (y - st.y_lp)
        y = st.y_lp
    y += p.noise_x * nx
    if p.quantum > 0.0:
        # np.floor stays a float: math.floor is an int64 in Numba, which wraps once y/quantum passes
        # 2^63 (a quantum of 1e-300 m measured every position as -9e-282 m: the arm never moved)
        y = np.floor(y / p.quantum + 0.5) * p.quantum
    if p.has_velocity != 0.0:
        yd += p.noise_v * nv
    else:
        yd = math.nan
    return y, yd

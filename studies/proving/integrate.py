"""The proving ground's own plant, controller and sensor, one compiled loop.

Shares no code with :mod:`kernels.plant` (the project's simulated drive): its own
integrator, its own friction and hysteresis families, its own sticking rule, its own
sensor.  Per sample ``k`` (period ``dt``) the recorded command ``u[k]`` is held over
``[t_k, t_k + dt)`` (zero-order hold), clipped at ``u_max[k]`` and delayed by
``delay`` seconds (a fractional delay splits the interval in two held pieces); each
piece is integrated with ``nsub`` sub-steps.

Force balance (force unit F, positions m)::

    J*x'' = kf(x)*u_app - B*x' - D(x') - gate[k]*H - K*x - h0 - cog(x)

* ``D``: dry friction with **Karnopp** sticking: at rest the arm stays put while the
  net force is within the breakaway level ``Fs``; moving, ``D = sgn(x')*(Fc + (Fs -
  Fc)*phi(|x'|/vs))`` with the Stribeck shape ``phi`` one of exponential ``exp(-r)``,
  Gaussian ``exp(-r^2)``, Lorentzian ``1/(1 + r^2)`` or a power ``exp(-r^delta)``.  The
  direction is frozen over a sub-step (the sign at its start); when the velocity
  changes sign inside a sub-step and the net force is within breakaway, it sticks.
* ``H``: a hysteresis family, advanced along the position increment of each sub-step
  after the rigid step (operator splitting): **LuGre** (bristle state, exact
  exponential update in position, ``H = sigma0*z + sigma1*z'``; its level ``g``
  constant, or with ``lg_vs > 0`` the Stribeck level ``g(v) = level*exp(-(v/lg_vs)^2)``
  of the full LuGre model, ``v`` the sub-step's mean speed), **Bouc-Wen** (n = 1,
  ``dz/dx = A - beta*sgn(dx)*z - gamma*|z|``, one RK4 step in position (split where
  the increment exceeds ``1/(beta + gamma)``), ``H = kbw*z``),
  **Maxwell-slip** (``N`` elasto-slide elements, deflection clipped at its slip
  distance, ``H = sum k_i*e_i``); ``gate[k]`` switches it on in part of the recording.
* Optional flexible mode ``q'' + 2*zeta*w*q' + w^2*q = u_app/J`` (RK4 with the rigid
  body) adding ``gain*q`` to the measured position.
* Optional further flexible modes (:func:`run_full`, rows ``(hz, zeta, gain)`` of
  ``modes``, up to the Nyquist frequency): each ``q_i'' + 2*zeta_i*w_i*q_i' +
  w_i^2*q_i = u_app/J`` advanced *exactly* over each held piece (a linear system
  under a constant force: its free damped oscillation about the static deflection), so
  a mode near ``fs/2`` keeps its frequency, adding ``gain_i*q_i`` to the measured position.
* Optional input **dead zone** of half-width ``deadzone`` (F): the force applied is
  ``sgn(u)*max(|u| - deadzone, 0)`` of the (clipped, delayed) command.
* Optional **backlash** between motor and load of half-gap ``backlash`` (m): the arm
  above is the motor; the load, whose position the sensor reads, follows it through a
  play (the load's inertia neglected, held by its own friction while the gap is open):
  ``x_load`` moves only when ``|x - x_load|`` would exceed the half-gap (the play
  operator, advanced each sub-step).
* Optional **cubic spring** ``k3*x^3`` (F/m^3) beside ``K*x`` (hardening ``k3 > 0``,
  softening ``k3 < 0``).
* Optional **drift**: a per-sample force offset ``dist[k]`` (F) beside ``h0`` (a
  wandering bias, thermal drift), held over the sample.
* Sensor: first-order low-pass (cutoff ``sensor_hz``, 0 for none) of the position,
  additive noise (the caller's unit-variance sequence, white or coloured, times
  ``noise``), quantisation to a lattice of step ``quantum``.
* Controller: a discrete transfer function from the error ``r[k] - y[k]`` to the
  feedback command (``ctrl_b``, ``ctrl_a``, ``a[0] = 1``) plus an additive excitation
  ``w[k]``; open loop when ``closed`` is 0 (``u = w``).

All parameters travel in one float64 vector ``p`` indexed by the ``P_*`` constants.
"""
import math

import numpy as np
from numba import float64, int64, njit, void

# ---- parameter vector layout
P_J, P_B, P_K, P_H0, P_FC, P_FS, P_VS, P_SHAPE, P_DELTA, P_DV = range(10)
P_HYST, P_SIGMA0, P_SIGMA1, P_HLEVEL, P_BW_A, P_BW_BETA, P_BW_GAMMA, P_BW_K = range(10, 18)
P_MODE_HZ, P_MODE_ZETA, P_MODE_GAIN = range(18, 21)
P_SENSOR_HZ, P_NOISE, P_QUANTUM, P_DELAY, P_CLOSED, P_NSUB = range(21, 27)
P_KF1, P_COG_AMP, P_COG_PERIOD, P_X0, P_RATE = range(27, 32)
P_DEADZONE, P_BACKLASH, P_K3, P_LG_VS = range(32, 36)
N_PARAMS = 36

SHAPE_EXP, SHAPE_GAUSS, SHAPE_LORENTZ, SHAPE_POWER = 0.0, 1.0, 2.0, 3.0
HYST_NONE, HYST_LUGRE, HYST_BOUCWEN, HYST_MAXWELL = 0.0, 1.0, 2.0, 3.0


@njit(float64(float64, float64[::1]), cache=True)
def stribeck(speed, p):
    """Sliding friction level at ``speed`` >= 0 (F)."""
    fc, fs, vs = p[P_FC], p[P_FS], p[P_VS]
    if fs == fc or vs <= 0.0:
        return fc
    r = speed / vs
    sh = p[P_SHAPE]
    if sh == SHAPE_EXP:
        phi = math.exp(-r)
    elif sh == SHAPE_GAUSS:
        phi = math.exp(-r * r)
    elif sh == SHAPE_LORENTZ:
        phi = 1.0 / (1.0 + r * r)
    else:
        phi = math.exp(-(r ** p[P_DELTA]))
    return fc + (fs - fc) * phi


@njit(float64(float64, float64, float64, float64[::1]), cache=True)
def external(x, u_app, hforce, p):
    """Net force on the arm except viscous and dry friction (F)."""
    kf = 1.0 + p[P_KF1] * x
    cog = 0.0
    if p[P_COG_AMP] != 0.0:
        cog = p[P_COG_AMP] * math.sin(2.0 * math.pi * x / p[P_COG_PERIOD])
    f = kf * u_app - hforce - p[P_K] * x - p[P_H0] - cog
    if p[P_K3] != 0.0:
        f -= p[P_K3] * x * x * x
    return f


@njit(float64(float64, float64, float64, float64, float64, float64[::1]), cache=True)
def accel(x, v, u_app, hforce, s, p):
    """Rigid-body acceleration with the dry friction's direction frozen at ``s``."""
    f = external(x, u_app, hforce, p) - p[P_B] * v
    if s != 0.0:
        f -= s * stribeck(abs(v), p)
    return f / p[P_J]


@njit(float64(float64[::1], float64[::1], float64[::1], float64[::1]), cache=True)
def hyst_force(hs, p, mk, mdelta):
    """Force of the hysteresis element in state ``hs`` (F): ``hs[0]`` the LuGre or
    Bouc-Wen state, ``hs[1]`` the LuGre bristle rate, ``hs[2:]`` Maxwell-slip deflections."""
    h = p[P_HYST]
    if h == HYST_LUGRE:
        return p[P_SIGMA0] * hs[0] + p[P_SIGMA1] * hs[1]
    if h == HYST_BOUCWEN:
        return p[P_BW_K] * hs[0]
    if h == HYST_MAXWELL:
        f = 0.0
        for i in range(mk.shape[0]):
            f += mk[i] * hs[2 + i]
        return f
    return 0.0


@njit(void(float64[::1], float64, float64, float64[::1], float64[::1]), cache=True)
def hyst_advance(hs, dx, h, p, mdelta):
    """Advance the hysteresis state along a position increment ``dx`` taken in ``h`` s."""
    kind = p[P_HYST]
    if kind == HYST_LUGRE and dx != 0.0:
        g = p[P_HLEVEL]
        if p[P_LG_VS] > 0.0:  # LuGre with a Stribeck level: g(v) = level*exp(-(v/vs)^2)
            r = abs(dx) / h / p[P_LG_VS]
            g = max(g * math.exp(-r * r), 1e-12 * p[P_HLEVEL])
        z_ss = math.copysign(g / p[P_SIGMA0], dx)
        z0 = hs[0]
        hs[0] = z_ss + (z0 - z_ss) * math.exp(-p[P_SIGMA0] * abs(dx) / g)
        hs[1] = (hs[0] - z0) / h
    elif kind == HYST_LUGRE:
        hs[1] = 0.0
    elif kind == HYST_BOUCWEN and dx != 0.0:
        A, be, ga = p[P_BW_A], p[P_BW_BETA], p[P_BW_GAMMA]
        sd = math.copysign(1.0, dx)
        # RK4 in position; an increment beyond 1/(beta + gamma) (a step's kick) is split in
        # pieces of half that, where RK4 on the decay rate beta + gamma is stable
        m = 1
        if abs(dx) * (be + ga) > 1.0:
            m = int(math.ceil(abs(dx) * (be + ga) / 0.5))
        d = dx / m
        z = hs[0]
        for _ in range(m):
            k1 = A - be * sd * z - ga * abs(z)
            z2 = z + 0.5 * d * k1
            k2 = A - be * sd * z2 - ga * abs(z2)
            z3 = z + 0.5 * d * k2
            k3 = A - be * sd * z3 - ga * abs(z3)
            z4 = z + d * k3
            k4 = A - be * sd * z4 - ga * abs(z4)
            z = z + d * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
        hs[0] = z
    elif kind == HYST_MAXWELL:
        for i in range(mdelta.shape[0]):
            e = hs[2 + i] + dx
            d = mdelta[i]
            hs[2 + i] = d if e > d else (-d if e < -d else e)


@njit(void(float64[:, ::1], float64[::1], float64, float64, float64), cache=True)
def modes_advance(modes, ms, force, dur, J):
    """Advance the further modes (rows ``(hz, zeta, gain)`` of ``modes``; states ``ms[2i]``,
    ``ms[2i+1]`` their deflection and rate) exactly over ``dur`` s under the constant
    ``force`` (F): the deviation from the static deflection ``force/(J*w^2)`` is a free
    damped oscillation (underdamped, ``zeta < 1``)."""
    for i in range(modes.shape[0]):
        w = 2.0 * math.pi * modes[i, 0]
        zeta = modes[i, 1]
        wd = w * math.sqrt(1.0 - zeta * zeta)
        qs = force / (J * w * w)
        e0, ed0 = ms[2 * i] - qs, ms[2 * i + 1]
        decay = math.exp(-zeta * w * dur)
        c, sn = math.cos(wd * dur), math.sin(wd * dur)
        b = (ed0 + zeta * w * e0) / wd
        e = decay * (e0 * c + b * sn)
        ed = decay * (ed0 * c - (e0 * wd + zeta * w * b) * sn)
        ms[2 * i] = qs + e
        ms[2 * i + 1] = ed


@njit(void(float64[::1], float64, float64, float64, float64, float64[::1], float64[::1], float64[::1], float64[::1],
           float64[:, ::1], float64[::1]), cache=True)
def piece(st, u_app, dur, gate, dist, hs, p, mk, mdelta, modes, ms):
    """Integrate the state ``st`` = [x, v, q, qd, stuck, x_load] over ``dur`` s under
    ``u_app`` with the force offset ``dist``; the further modes' states ``ms``."""
    n = int(p[P_NSUB])
    h = dur / n
    w = 2.0 * math.pi * p[P_MODE_HZ]
    zeta = p[P_MODE_ZETA]
    J = p[P_J]
    gap = p[P_BACKLASH]
    for _ in range(n):
        x, v, q, qd = st[0], st[1], st[2], st[3]
        hf = gate * hyst_force(hs, p, mk, mdelta)
        if dist != 0.0:
            hf += dist
        if modes.shape[0] > 0:
            modes_advance(modes, ms, u_app, h, J)
        # the flexible mode: linear, RK4
        if w > 0.0:
            a1 = u_app / J - 2 * zeta * w * qd - w * w * q
            q2, qd2 = q + 0.5 * h * qd, qd + 0.5 * h * a1
            a2 = u_app / J - 2 * zeta * w * qd2 - w * w * q2
            q3, qd3 = q + 0.5 * h * qd2, qd + 0.5 * h * a2
            a3 = u_app / J - 2 * zeta * w * qd3 - w * w * q3
            q4, qd4 = q + h * qd3, qd + h * a3
            a4 = u_app / J - 2 * zeta * w * qd4 - w * w * q4
            st[2] = q + h * (qd + 2 * qd2 + 2 * qd3 + qd4) / 6.0
            st[3] = qd + h * (a1 + 2 * a2 + 2 * a3 + a4) / 6.0
        # Karnopp: at rest, stay while the net force is within breakaway
        if v == 0.0:
            fe = external(x, u_app, hf, p)
            if abs(fe) <= p[P_FS]:
                hyst_advance(hs, 0.0, h, p, mdelta)
                continue
            s = math.copysign(1.0, fe)
        else:
            s = math.copysign(1.0, v)
        k1x, k1v = v, accel(x, v, u_app, hf, s, p)
        k2x, k2v = v + 0.5 * h * k1v, accel(x + 0.5 * h * k1x, v + 0.5 * h * k1v, u_app, hf, s, p)
        k3x, k3v = v + 0.5 * h * k2v, accel(x + 0.5 * h * k2x, v + 0.5 * h * k2v, u_app, hf, s, p)
        k4x, k4v = v + h * k3v, accel(x + h * k3x, v + h * k3v, u_app, hf, s, p)
        xn = x + h * (k1x + 2 * k2x + 2 * k3x + k4x) / 6.0
        vn = v + h * (k1v + 2 * k2v + 2 * k3v + k4v) / 6.0
        if vn * s < 0.0 or abs(vn) < p[P_DV]:  # reversal (or standstill) inside the sub-step
            if abs(external(xn, u_app, hf, p)) <= p[P_FS]:
                vn = 0.0
        st[0], st[1] = xn, vn
        hyst_advance(hs, xn - x, h, p, mdelta)
        if gap > 0.0:  # the play operator: the load moves only when the gap is taken up
            if xn - st[5] > gap:
                st[5] = xn - gap
            elif xn - st[5] < -gap:
                st[5] = xn + gap


@njit(void(float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1],
           float64[::1], float64[::1], float64[::1], float64[::1], float64[:, ::1], float64[::1], float64[::1],
           float64[::1], int64), cache=True)
def run_full(p, r, w, u_max, gate, noise, ctrl_b, ctrl_a, mk, mdelta, dist, modes, u_out, y_out, x_out, n):
    """Simulate ``n`` samples (module doc).  ``r``, ``w``, ``u_max``, ``gate``, ``noise``,
    ``dist`` (n,): reference (m), excitation (F), clip level (F), hysteresis gate,
    unit-variance sensor noise (white or coloured), force offset (F); ``modes`` (m, 3):
    further modes ``(hz, zeta, gain)``; writes the recorded command ``u_out``, measured
    ``y_out`` and true ``x_out`` positions (n,), ``x_out`` the motor's."""
    dt = 1.0 / p[P_RATE]
    st = np.zeros(6)
    st[0] = p[P_X0]
    st[5] = p[P_X0]
    ms = np.zeros(2 * modes.shape[0])
    hs = np.zeros(2 + mk.shape[0])
    nb, na = ctrl_b.shape[0], ctrl_a.shape[0]
    e_hist = np.zeros(nb)
    u_hist = np.zeros(na)
    ylp = p[P_X0]
    alp = 1.0 - math.exp(-2.0 * math.pi * p[P_SENSOR_HZ] * dt) if p[P_SENSOR_HZ] > 0 else 1.0
    m_whole = int(math.floor(p[P_DELAY] / dt))
    frac = p[P_DELAY] / dt - m_whole
    dz = p[P_DEADZONE]
    for k in range(n):
        # sensor
        meas = (st[5] if p[P_BACKLASH] > 0.0 else st[0]) + p[P_MODE_GAIN] * st[2]
        for i in range(modes.shape[0]):
            meas += modes[i, 2] * ms[2 * i]
        ylp += alp * (meas - ylp)
        y = ylp + p[P_NOISE] * noise[k]
        if p[P_QUANTUM] > 0.0:
            y = p[P_QUANTUM] * math.floor(y / p[P_QUANTUM] + 0.5)
        y_out[k] = y
        x_out[k] = st[0]
        # controller
        if p[P_CLOSED] != 0.0:
            for i in range(nb - 1, 0, -1):
                e_hist[i] = e_hist[i - 1]
            e_hist[0] = r[k] - y
            ufb = 0.0
            for i in range(nb):
                ufb += ctrl_b[i] * e_hist[i]
            for i in range(1, na):
                ufb -= ctrl_a[i] * u_hist[i - 1]
            for i in range(na - 1, 0, -1):
                u_hist[i] = u_hist[i - 1]
            u_hist[0] = ufb
            u = ufb + w[k]
        else:
            u = w[k]
        u_out[k] = u
        # the plant over [t_k, t_k + dt): the delayed, clipped command
        k_new, k_old = k - m_whole, k - m_whole - 1
        u_new = u_out[k_new] if k_new >= 0 else 0.0
        u_old = u_out[k_old] if k_old >= 0 else 0.0
        u_new = min(max(u_new, -u_max[k]), u_max[k])
        u_old = min(max(u_old, -u_max[k]), u_max[k])
        if dz > 0.0:  # the input dead zone
            u_new = math.copysign(max(abs(u_new) - dz, 0.0), u_new)
            u_old = math.copysign(max(abs(u_old) - dz, 0.0), u_old)
        if frac > 0.0:
            piece(st, u_old, frac * dt, gate[k], dist[k], hs, p, mk, mdelta, modes, ms)
            piece(st, u_new, (1.0 - frac) * dt, gate[k], dist[k], hs, p, mk, mdelta, modes, ms)
        else:
            piece(st, u_new, dt, gate[k], dist[k], hs, p, mk, mdelta, modes, ms)


@njit(void(float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1],
           float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], int64), cache=True)
def run(p, r, w, u_max, gate, noise, ctrl_b, ctrl_a, mk, mdelta, u_out, y_out, x_out, n):
    """:func:`run_full` without a force offset or further modes (the first proving
    ground's signature)."""
    run_full(p, r, w, u_max, gate, noise, ctrl_b, ctrl_a, mk, mdelta, np.zeros(n), np.zeros((0, 3)), u_out, y_out,
             x_out, n)


__all__ = ["N_PARAMS", "run", "run_full"]

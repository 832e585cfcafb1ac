"""Compiled driver loops: each kernel called ``n`` times inside one Numba loop.

A benchmark times one call of a loop and divides by ``n`` to get the per-sample cost of
the kernel as it runs in the all-compiled path (Numba links the kernel into the loop, as
it does into the composed fast path of :mod:`kernels.compose`).  Two guards against an optimiser that
would time nothing: the inputs vary every sample (read from a table of ``M`` rows,
indexed ``k & (M - 1)``), and every output is accumulated into the value returned.
Kernel state (Dahl turnaround, integrator, plant) is carried from sample to sample, as in
a run.  Explicit signatures and ``cache=True``, like the kernels: importing this module
compiles (or loads) every loop before any timing starts.
"""
from numba import float64, from_dtype, int64

from kernels._cache import kernel
from kernels.compensator import compensate
from kernels.dahl import dahl_update
from kernels.delay import shift_in
from kernels.holding import holding_pi
from kernels.plant import plant_measure, plant_params_t, plant_state_t, plant_step
from kernels.stage import stage_params_t, stage_state_t
from servo.controllers import nss, pi, track

#: Each kind's tick on its stage, on the records (:mod:`kernels.compose`), and the kinds'
#: record array types.
controller_step = pi.PI.kernels().servo_step
track_step = track.Track.kernels().servo_step
nss_step = nss.NSS.kernels().servo_step
pi_state_t, pi_params_t = from_dtype(pi.STATE)[::1], from_dtype(pi.PARAMS)[::1]
track_state_t, track_params_t = from_dtype(track.STATE)[::1], from_dtype(track.PARAMS)[::1]

#: Rows of an input table (a power of two: the row of sample k is ``k & (M - 1)``).
M = 4096


@kernel(float64(int64, float64[:, ::1], float64, float64, float64))
def loop_dahl_update(n, xin, sigma, Ha, alpha):
    """``dahl_update`` (eq. 6-7) on rows ``(x, s_new)`` of ``xin``; returns the sum of H (A)."""
    mask = xin.shape[0] - 1
    s, x_r, H_r, x_ext = 1.0, xin[0, 0], 0.0, xin[0, 0]
    acc = 0.0
    for k in range(n):
        j = k & mask
        s, x_r, H_r, x_ext, H = dahl_update(xin[j, 0], xin[j, 1], s, x_r, H_r, x_ext, sigma, Ha, alpha)
        acc += H
    return acc


@kernel(float64(int64, float64[:, ::1], float64[::1]))
def loop_compensate(n, xin, kp):
    """``compensate`` (eq. 9) on rows ``(regime, x, v, s, H)``; ``kp = (B, Fc, K, h0)``."""
    mask = xin.shape[0] - 1
    B, Fc, K, h0 = kp[0], kp[1], kp[2], kp[3]
    acc = 0.0
    for k in range(n):
        j = k & mask
        acc += compensate(int(xin[j, 0]), xin[j, 1], xin[j, 2], xin[j, 3], xin[j, 4], B, Fc, K, h0)
    return acc


@kernel(float64(int64, float64[:, ::1], float64[::1]))
def loop_holding_pi(n, xin, g):
    """``holding_pi`` on rows ``(e, e_p, v)``; ``g = (kp, ki, kd, dt, lo, hi)``; the
    integrator is carried.  Returns the sum of outputs (A)."""
    mask = xin.shape[0] - 1
    integ = 0.0
    acc = 0.0
    for k in range(n):
        j = k & mask
        u, integ = holding_pi(xin[j, 0], xin[j, 1], xin[j, 2], integ, 0.0, g[0], g[1], g[2], g[3], g[4], g[5])
        acc += u
    return acc


@kernel(float64(int64, float64[:, ::1], stage_state_t, stage_params_t, pi_state_t, pi_params_t))
def loop_controller_tick(n, xin, ss, sp, cs, cp):
    """The full controller tick (Dahl update + compensator + PI + limits) on rows
    ``(x, v_meas, r, u_exc)``.  Returns the sum of commands (A)."""
    mask = xin.shape[0] - 1
    s, p, c, q = ss[0], sp[0], cs[0], cp[0]  # the records, as the fast path passes them
    acc = 0.0
    for k in range(n):
        j = k & mask
        acc += controller_step(s, p, c, q, xin[j, 0], xin[j, 1], xin[j, 2], xin[j, 3])
    return acc


@kernel(float64(int64, float64[:, ::1], stage_state_t, stage_params_t, track_state_t, track_params_t))
def loop_track_tick(n, xin, ss, sp, cs, cp):
    """The track-following kind's tick on its stage, rows as :func:`loop_controller_tick`."""
    mask = xin.shape[0] - 1
    s, p, c, q = ss[0], sp[0], cs[0], cp[0]
    acc = 0.0
    for k in range(n):
        j = k & mask
        acc += track_step(s, p, c, q, xin[j, 0], xin[j, 1], xin[j, 2], xin[j, 3])
    return acc


@kernel(float64(int64, float64[:, ::1], stage_state_t, stage_params_t, track_state_t, track_params_t))
def loop_nss_tick(n, xin, ss, sp, cs, cp):
    """The NSS reference kind's tick on its stage, rows as :func:`loop_controller_tick`."""
    mask = xin.shape[0] - 1
    s, p, c, q = ss[0], sp[0], cs[0], cp[0]
    acc = 0.0
    for k in range(n):
        j = k & mask
        acc += nss_step(s, p, c, q, xin[j, 0], xin[j, 1], xin[j, 2], xin[j, 3])
    return acc


@kernel(
    float64(int64, float64[:, ::1], plant_state_t, plant_params_t, float64[:, ::1], float64[:, :, ::1], float64[::1]),
)
def loop_plant_step(n, uin, ps, pp, q, mab, ubuf):
    """``plant_step`` (RK4 sub-steps, Dahl pivot, modes, input delay) on rows ``(u, d)``.
    Returns the sum of rigid-body positions (m)."""
    mask = uin.shape[0] - 1
    acc = 0.0
    for k in range(n):
        j = k & mask
        plant_step(ps, pp, q, mab, ubuf, uin[j, 0], uin[j, 1])
        acc += ps[0].x
    return acc


@kernel(float64(int64, float64[:, ::1], plant_state_t, plant_params_t, float64[:, ::1], float64[::1]))
def loop_plant_measure(n, noise, ps, pp, q, gain):
    """``plant_measure`` (modes, noise, quantisation) with rows ``(nx, nv)`` of ``noise``."""
    mask = noise.shape[0] - 1
    acc = 0.0
    for k in range(n):
        j = k & mask
        x, v = plant_measure(ps, pp, q, gain, noise[j, 0], noise[j, 1])
        acc += x + v
    return acc


@kernel(float64(int64, float64[:, ::1], float64[::1]))
def loop_shift_in(n, uin, buf):
    """``shift_in`` (the link's command queue) on ``uin[:, 0]``; returns the sum out (A)."""
    mask = uin.shape[0] - 1
    acc = 0.0
    for k in range(n):
        acc += shift_in(buf, uin[k & mask, 0])
    return acc


@kernel(
    float64(
        int64, float64[:, ::1], float64[:, ::1],
        plant_state_t, plant_params_t, float64[:, ::1], float64[:, :, ::1], float64[::1], float64[::1],
        stage_state_t, stage_params_t, pi_state_t, pi_params_t,
    ),
)  # fmt: skip
def loop_closed(n, ref, noise, ps, pp, q, mab, gain, ubuf, ss, sp, cs, cp):
    """Closed loop without logging: ``plant_measure -> controller_tick -> plant_step``;
    ``ref`` rows ``(r, u_exc, d)``.  Returns the sum of commands (A)."""
    mask = ref.shape[0] - 1
    s, sp0, c, cp0 = ss[0], sp[0], cs[0], cp[0]
    acc = 0.0
    for k in range(n):
        j = k & mask
        x, v = plant_measure(ps, pp, q, gain, noise[j, 0], noise[j, 1])
        u = controller_step(s, sp0, c, cp0, x, v, ref[j, 0], ref[j, 1])
        plant_step(ps, pp, q, mab, ubuf, u, ref[j, 2])
        acc += u
    return acc

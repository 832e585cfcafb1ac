"""The all-compiled fast path: controller and simulated drive in one Numba loop.

It performs exactly the operations of the tick-by-tick path (``servo.runtime.scheduler``), in the
same order and through the same kernels, so both give the same bits:

    tick k:  plant_measure -> [controller_start on the first tick]
             -> [excitation every exc_every] -> controller_tick
             -> link latency -> plant_step -> [estimator every est_every]
             -> [log row every log_every]
"""
from numba import float64, int64, njit, void

from kernels.controller import controller_start, controller_tick, ctrl_params_t, ctrl_state_t
from kernels.delay import shift_in
from kernels.plant import plant_measure, plant_params_t, plant_state_t, plant_step

#: Columns of a run log, in order.  Units: tick (-), t (s), r x (m), v (m/s),
#: u u_n u_c u_exc h_hat (A), regime (0 SLOW / 1 FAST), e (m).
LOG_COLUMNS = ("tick", "t", "r", "x", "v", "u", "u_n", "u_c", "u_exc", "h_hat", "regime", "e")
#: The unit of each column of :data:`LOG_COLUMNS`.
LOG_UNITS = dict(zip(LOG_COLUMNS, ("-", "s", "m", "m", "m/s", "A", "A", "A", "A", "A", "-", "m")))

#: Accumulators of the tracking-error estimator: sum of e^2, count, max |e|.
STATS_SIZE = 3


@njit(void(float64[::1], int64, float64, float64, float64, ctrl_state_t), cache=True)
def log_row(row, k, dt, x, u_exc, cs):
    """Fill one log row (see :data:`LOG_COLUMNS`) from the controller state of tick ``k``."""
    c = cs[0]
    row[0] = k
    row[1] = k * dt
    row[2] = c.x_prev + c.e  # absolute reference: x + (r - x)
    row[3] = x
    row[4] = c.v
    row[5] = c.u
    row[6] = c.u_n
    row[7] = c.u_c
    row[8] = u_exc
    row[9] = c.H_dahl
    row[10] = c.regime
    row[11] = c.e


@njit(void(float64[::1], float64), cache=True)
def error_stats(stats, e):
    """The tracking-error estimator: accumulate ``e`` (m) into ``stats``."""
    stats[0] += e * e
    stats[1] += 1.0
    if abs(e) > stats[2]:
        stats[2] = abs(e)


@njit(
    int64(
        plant_state_t,
        plant_params_t,
        float64[:, ::1],
        float64[:, :, ::1],
        float64[::1],
        float64[::1],
        float64[::1],
        ctrl_state_t,
        ctrl_params_t,
        float64[::1],
        float64[::1],
        float64[::1],
        float64[:, ::1],
        int64,
        int64,
        int64,
        int64,
        float64[::1],
        float64[:, ::1],
        int64,
        int64,
        float64,
    ),
    cache=True,
)
def closed_loop(
    ps, pp, q, mab, gain, ubuf, latency,
    cs, cp,
    r, u_exc, d, noise,
    k0, n, est_every, log_every,
    stats, log, row,
    start, u_start,
):  # fmt: skip
    """Run ticks ``k0 .. k0+n-1`` of the closed loop against the simulated drive.

    Plant: state ``ps``, params ``pp``, modes ``q``/``mab``/``gain``, input-delay buffer
    ``ubuf``; ``latency`` the link's command queue (length = latency in ticks).
    Controller: ``cs``/``cp``.  Inputs of tick k at index ``k - k0``: reference ``r`` (m)
    and excitation ``u_exc`` (A) as the excitation task holds them (sampled every
    ``run.excitation_every`` ticks, see :class:`servo.runtime.scenario.Window`),
    disturbance ``d`` (A), ``noise`` the two standard normal draws.  Logs every ``log_every`` ticks into ``log[row]`` onwards and
    returns the next free row.  ``start != 0``: the controller takes over at ``k0`` with
    ``u_start`` (A) applied (:func:`kernels.controller.controller_start`).
    """
    dt = pp[0].dt
    for k in range(k0, k0 + n):
        x, v = plant_measure(ps, pp, q, gain, noise[k - k0, 0], noise[k - k0, 1])
        if start != 0 and k == k0:
            controller_start(cs, cp, x, v, u_start)
        i = k - k0
        u = controller_tick(cs, cp, x, v, r[i], u_exc[i])
        plant_step(ps, pp, q, mab, ubuf, shift_in(latency, u), d[i])
        if k % est_every == 0:
            error_stats(stats, cs[0].e)
        if k % log_every == 0:
            log_row(log[row], k, dt, x, u_exc[i], cs)
            row += 1
    return row

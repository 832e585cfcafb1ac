"""One controller kind composed with the stage, the log row and the all-compiled loop.

A controller kind brings three compiled kernels on its own records ``c`` (state) and
``p`` (parameters): the records themselves (``cs[0]``, ``cp[0]`` of one-element record
arrays of its own dtypes), which numba passes by reference, with no reference counting
per call:

* ``start(c, p, x, v, u_n)``: take over bumplessly at position ``x`` (m), velocity
  ``v`` (m/s), with ``u_n`` (A) the nominal input its first output must equal;
* ``tick(c, p, x, v, r_base, r, u_exc, lo, hi) -> u_n``: one sample; ``r_base + r``
  (m) the reference, ``u_exc`` (A) an excitation to add, ``[lo, hi]`` (A) the room the
  stage leaves for ``u_n`` under the current limit;
* ``log(out, c)``: its own log columns into ``out`` (a view of the row, may be empty).

:func:`compose` builds, for that kind, the kernels the runtime calls, on one record
array ``buf`` of :func:`records_dtype` holding the four records (stage state and
parameters, the kind's state and parameters: one argument, so that a call from Python
pays one argument's type check, ~0.3 us, not four):

* ``servo_start(buf, x, v_meas, u_now)`` and ``servo_tick(buf, x, v_meas, r, u_exc) -> u``:
  the kind inside the stage of :mod:`kernels.stage` (signals, compensator, limit);
  ``servo_step(s, p, c, q, x, v_meas, r, u_exc) -> u`` the same on the four records;
* ``log_row(row, k, dt, x, u_exc, buf)``: the columns :data:`LOG_COLUMNS` then the
  kind's own;
* ``closed_loop(...)``: the all-compiled fast path against the simulated drive, the same
  operations in the same order as the tick-by-tick path (``servo.runtime.scheduler``),
  so both give the same bits::

      tick k:  plant_measure -> [servo_start on the first tick] -> servo_tick
               -> link latency -> plant_step -> [estimator every est_every]
               -> [log row every log_every, the run watchdog's tests of it]

The kernels are the templates below compiled with the kind's kernels in their globals
and the kind's record types in their signatures, ``cache=True``: each kind gets its own
cache entries, named after the kind and a tag that changes with the kind's source
(:func:`compose`'s ``tag``), so an edited controller never runs stale machine code.
"""
from __future__ import annotations

import types
from typing import NamedTuple

import numpy as np
from numba import float64, from_dtype, int64, uint8, void

from kernels._cache import kernel
from kernels.delay import shift_in
from kernels.plant import plant_measure, plant_params_t, plant_state_t, plant_step
from kernels.stage import (
    STAGE_PARAMS, STAGE_STATE, stage_output, stage_params_rec_t, stage_room, stage_start, stage_state_rec_t,
    stage_update,
)  # fmt: skip
from kernels.watch import watch_row

#: Columns every run log starts with.  Units: tick (-), t (s), r x (m), v (m/s),
#: u u_n u_c u_exc h_hat (A), regime (0 SLOW / 1 FAST), e (m).
LOG_COLUMNS = ("tick", "t", "r", "x", "v", "u", "u_n", "u_c", "u_exc", "h_hat", "regime", "e")
#: The unit of each column of :data:`LOG_COLUMNS`.
LOG_UNITS = dict(zip(LOG_COLUMNS, ("-", "s", "m", "m", "m/s", "A", "A", "A", "A", "A", "-", "m")))
N_COMMON = len(LOG_COLUMNS)
_IX, _IU = LOG_COLUMNS.index("x"), LOG_COLUMNS.index("u")  # the columns the run watchdog tests

#: Accumulators of the tracking-error estimator: sum of e^2, count, max |e|.
STATS_SIZE = 3


@kernel(void(float64[::1], float64))
def error_stats(stats, e):
    """The tracking-error estimator: accumulate ``e`` (m) into ``stats``."""
    stats[0] += e * e
    stats[1] += 1.0
    if abs(e) > stats[2]:
        stats[2] = abs(e)


# ------------------------------------------------------------------ templates
# ctrl_start, ctrl_tick and ctrl_log are names the templates leave free: compose() gives
# each compiled copy a globals dict in which they are the kind's kernels.


def _servo_start(buf, x, v_meas, u_now):
    b = buf[0]
    s = b.stage_state
    u_n = stage_start(s, b.stage_params, x, v_meas, u_now)
    ctrl_start(b.state, b.params, x, s.v, u_n)  # noqa: F821


def _servo_step(s, p, c, q, x, v_meas, r, u_exc):
    u_c = stage_update(s, p, x, v_meas)
    lo, hi = stage_room(p, u_c, x)
    u_n = ctrl_tick(c, q, x, s.v, s.r_base, r, u_exc, lo, hi)  # noqa: F821
    return stage_output(s, p, x, r, u_n, u_c)


def _servo_tick(buf, x, v_meas, r, u_exc):
    b = buf[0]
    return servo_step(b.stage_state, b.stage_params, b.state, b.params, x, v_meas, r, u_exc)  # noqa: F821


def _log_row(row, k, dt, x, u_exc, buf):
    c = buf[0].stage_state
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
    ctrl_log(row[12:], buf[0].state)  # noqa: F821


def _closed_loop(
    ps, pp, q, mab, gain, ubuf, latency,
    buf,
    r, u_exc, d, noise,
    k0, n, est_every, log_every,
    stats, log, row,
    start, u_start,
    watch, ring, carry,
):  # fmt: skip
    dt = pp[0].dt
    b = buf[0]
    s, sp0, c, cp0 = b.stage_state, b.stage_params, b.state, b.params
    for k in range(k0, k0 + n):
        x, v = plant_measure(ps, pp, q, gain, noise[k - k0, 0], noise[k - k0, 1])
        if start != 0 and k == k0:
            servo_start(buf, x, v, u_start)  # noqa: F821
        i = k - k0
        u = servo_step(s, sp0, c, cp0, x, v, r[i], u_exc[i])  # noqa: F821
        plant_step(ps, pp, q, mab, ubuf, shift_in(latency, u), d[i])
        if k % est_every == 0:
            error_stats(stats, s.e)
        if k % log_every == 0:
            log_row(log[row], k, dt, x, u_exc[i], buf)  # noqa: F821
            watch_row(log[row, _IX], log[row, _IU], row, watch, ring, carry)  # while the row is in cache
            row += 1
    return row


_closed_loop.__doc__ = """Run ticks ``k0 .. k0+n-1`` of the closed loop against the simulated drive.

Plant: state ``ps``, params ``pp``, modes ``q``/``mab``/``gain``, input-delay buffer
``ubuf``; ``latency`` the link's command queue (length = latency in ticks).  ``buf``: the
stage's and the controller's records (:func:`records_dtype`).  Inputs of tick k at index ``k - k0``:
reference ``r`` (m) and excitation ``u_exc`` (A) as the excitation task holds them
(:class:`servo.runtime.window.Window`), disturbance ``d`` (A), ``noise`` the two
standard normal draws.  Logs every ``log_every`` ticks into ``log[row]`` onwards and
returns the next free row.  ``start != 0``: the controller takes over at ``k0`` with
``u_start`` (A) applied.  ``watch``, ``ring``, ``carry``: the run watchdog's tests of
each logged row (:func:`kernels.watch.watch_row`), done as the row is written."""


class Composed(NamedTuple):
    """The compiled kernels of one controller kind (see the module docstring)."""

    dtype: object
    servo_start: object
    servo_tick: object
    servo_step: object
    log_row: object
    closed_loop: object


def _specialise(template, name: str, env: dict, signature, **options):
    """``template`` compiled under ``name`` with ``env`` added to its globals (``options``:
    Numba's, e.g. ``nogil``)."""
    g = dict(template.__globals__)
    g.update(env)
    fn = types.FunctionType(template.__code__, g, name)
    fn.__qualname__ = name
    fn.__doc__ = template.__doc__
    return kernel(signature, **options)(fn)


_COMPOSED: dict[tuple, Composed] = {}


def records_dtype(state_dtype, params_dtype):
    """The dtype of one controller's ``buf``: fields ``stage_state``, ``stage_params``
    (:mod:`kernels.stage`), ``state``, ``params`` (the kind's)."""
    return np.dtype([("stage_state", STAGE_STATE), ("stage_params", STAGE_PARAMS),
                     ("state", state_dtype), ("params", params_dtype)])  # fmt: skip


def compose(name: str, tag: str, state_dtype, params_dtype, start, tick, log) -> Composed:
    """The kernels of controller kind ``name`` (compiled, or loaded from the cache, once
    per process).  ``tag``: a short hash of the kind's source (part of the cache names);
    ``state_dtype``/``params_dtype``: its record dtypes; ``start``/``tick``/``log``: its
    kernels, with the signatures of the module docstring."""
    key = (name, tag)
    if key in _COMPOSED:
        return _COMPOSED[key]
    c_t, p_t = from_dtype(state_dtype), from_dtype(params_dtype)
    dtype = records_dtype(state_dtype, params_dtype)
    buf_t = from_dtype(dtype)[::1]
    base = f"{name}_{tag}"
    env = {"ctrl_start": start, "ctrl_tick": tick, "ctrl_log": log}
    s_start = _specialise(
        _servo_start, f"servo_start_{base}", env,
        void(buf_t, float64, float64, float64),
    )  # fmt: skip
    # servo_step is called by the other kernels only, and closed_loop by the fast path
    # alone (which checks it on scratch copies before its loop): both load when first
    # needed (kernels._cache.kernel's helpers), so a tick-path run does not pay for them.
    s_step = _specialise(
        _servo_step, f"servo_step_{base}", env,
        float64(stage_state_rec_t, stage_params_rec_t, c_t, p_t, float64, float64, float64, float64),
        helper=True,
    )  # fmt: skip
    s_tick = _specialise(
        _servo_tick, f"servo_tick_{base}", {"servo_step": s_step},
        float64(buf_t, float64, float64, float64, float64),
    )  # fmt: skip
    s_log = _specialise(
        _log_row, f"log_row_{base}", env,
        void(float64[::1], int64, float64, float64, float64, buf_t),
    )  # fmt: skip
    env = {"servo_start": s_start, "servo_step": s_step, "log_row": s_log}
    s_loop = _specialise(
        _closed_loop, f"closed_loop_{base}", env,
        int64(
            plant_state_t, plant_params_t, float64[:, ::1], float64[:, :, ::1], float64[::1], float64[::1],
            float64[::1], buf_t,
            float64[::1], float64[::1], float64[::1], float64[:, ::1],
            int64, int64, int64, int64, float64[::1], float64[:, ::1], int64, int64, float64,
            float64[::1], uint8[::1], int64[::1],
        ),
        nogil=True,  # a block of ticks runs while the run log's writer thread journals the last
        helper=True,
    )  # fmt: skip
    out = _COMPOSED[key] = Composed(dtype, s_start, s_tick, s_step, s_log, s_loop)
    return out


def composed_kernels() -> list:
    """Every kernel :func:`compose` built in this process (for cache accounting)."""
    return [k for c in _COMPOSED.values() for k in c[1:]]

"""The run watchdog's tests of logged rows (:mod:`servo.runtime.watchdog`), one pass.

The current-limit test slides a window over the rows: a ring of the last ``window``
at-limit flags and their count carry from one chunk of rows to the next, so a look costs
a few ns per new row whatever the window's length (a NumPy version re-summed the whole
window at every look: ~20 us per 1024 rows with a 2500-row window).

The per-row tests, :func:`outside` and :func:`slide`, are shared by the scans of the tick
path (:func:`first_outside`, :func:`first_over_share`, over rows already logged) and the
compiled fast path (:func:`watch_row`, called by :mod:`kernels.compose`'s loop on each row
as it logs it, while the row is in cache).  ``carry`` holds, as int64: the flags in the
ring, the rows seen, the next slot, then for :func:`watch_row` the first row outside
(-1: none), the first row at which the window held too many flags (-1: none) and that
count: :data:`CARRY_SIZE` in all.
"""
from numba import boolean, float64, int64, types, uint8, void

from kernels._cache import kernel

#: Length of the watchdog's ``carry`` (see the module docstring).
CARRY_SIZE = 6


@kernel(boolean(float64, float64), helper=True)
def outside(x, position):
    """Whether ``x`` (m) is not within ``+-position`` (NaN counts as outside)."""
    return not (abs(x) < position)


# inlined into its callers: a call handed the arrays would count their references each row
@kernel(int64(float64, float64, uint8[::1], int64[::1]), inline="always", helper=True)
def slide(u, limit, ring, carry):
    """Flag ``|u| >= limit`` (A) into ``ring`` (the last ``len(ring)`` flags, 0 or 1) and
    ``carry[:3]`` = [flags in the ring, rows seen, next slot].  Returns the flags in the
    ring once it is full (a whole window seen), else -1."""
    w = ring.shape[0]
    count, seen, slot = carry[0], carry[1], carry[2]
    f = 1 if abs(u) >= limit else 0
    if seen >= w:
        count -= ring[slot]
    ring[slot] = f
    count += f
    slot += 1
    if slot == w:
        slot = 0
    seen += 1
    carry[0], carry[1], carry[2] = count, seen, slot
    return count if seen >= w else -1


@kernel(int64(float64[:, ::1], int64, float64))
def first_outside(rows, ix, position):
    """Index of the first row whose ``rows[:, ix]`` (m) is not within ``+-position``
    (NaN counts as outside), or -1."""
    for j in range(rows.shape[0]):
        if outside(rows[j, ix], position):
            return j
    return -1


@kernel(types.UniTuple(int64, 2)(float64[:, ::1], int64, float64, uint8[::1], int64[::1], float64))
def first_over_share(rows, iu, limit, ring, carry, most):
    """Slide the window on (:func:`slide`) over ``rows[:, iu]``.  Returns ``(j, count)``
    for the first row ``j`` at which a full window holds more than ``most`` flags, else
    ``(-1, 0)``."""
    for j in range(rows.shape[0]):
        count = slide(rows[j, iu], limit, ring, carry)
        if count > most:
            return j, count
    return -1, 0


@kernel(void(float64, float64, int64, float64[::1], uint8[::1], int64[::1]), inline="always", helper=True)
def watch_row(x, u, row, watch, ring, carry):
    """Both tests on log row ``row`` (position ``x``, m, command ``u``, A) as the compiled
    loop logs it: ``watch`` = [position, limit, most] (``most`` infinite: no limit test).
    The first row outside goes to ``carry[3]``, the first row over the share to
    ``carry[4]`` with its count in ``carry[5]``; once found, each test stops (the run
    stops at the end of the call)."""
    if carry[3] < 0 and outside(x, watch[0]):
        carry[3] = row
    if carry[4] < 0:
        count = slide(u, watch[1], ring, carry)
        if count > watch[2]:
            carry[4] = row
            carry[5] = count

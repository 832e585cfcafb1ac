"""The run watchdog's scan of logged rows (:mod:`servo.runtime.watchdog`), one pass.

The current-limit test slides a window over the rows: a ring of the last ``window``
at-limit flags and their count carry from one chunk of rows to the next, so a look costs
a few ns per new row whatever the window's length (a NumPy version re-summed the whole
window at every look: ~20 us per 1024 rows with a 2500-row window).
"""
from numba import float64, int64, types, uint8

from kernels._cache import kernel


@kernel(int64(float64[:, ::1], int64, float64))
def first_outside(rows, ix, position):
    """Index of the first row whose ``rows[:, ix]`` (m) is not within ``+-position``
    (NaN counts as outside), or -1."""
    for j in range(rows.shape[0]):
        if not (abs(rows[j, ix]) < position):
            return j
    return -1


@kernel(types.UniTuple(int64, 2)(float64[:, ::1], int64, float64, uint8[::1], int64[::1], float64))
def first_over_share(rows, iu, limit, ring, carry, most):
    """Slide the window on: for each row, flag ``|rows[:, iu]| >= limit`` (A) into
    ``ring`` (the last ``len(ring)`` flags, 0 or 1); ``carry`` = [flags in the ring,
    rows seen, next slot].  Returns ``(j, count)`` for the first row ``j`` at which a full
    window holds more than ``most`` flags, else ``(-1, 0)``."""
    w = ring.shape[0]
    count, seen, slot = carry[0], carry[1], carry[2]
    for j in range(rows.shape[0]):
        f = 1 if abs(rows[j, iu]) >= limit else 0
        if seen >= w:
            count -= ring[slot]
        ring[slot] = f
        count += f
        slot += 1
        if slot == w:
            slot = 0
        seen += 1
        if seen >= w and count > most:
            carry[0], carry[1], carry[2] = count, seen, slot
            return j, count
    carry[0], carry[1], carry[2] = count, seen, slot
    return -1, 0

"""A run's inputs read in windows of ticks.

A scenario's :class:`~servo.scenarios.base.Inputs` evaluates its three signals for any
array of tick indices, so a run of any length needs no array as long as the run: both the
tick-by-tick path and the compiled fast path read them through a :class:`Window` of
:data:`BLOCK` ticks, refilled as the run moves on.  A signal's value at a tick does not
depend on which window computed it, so both paths read the very same numbers.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

#: Ticks per input window (the same as the simulated drive's noise blocks).
BLOCK = 1024


class Window:
    """One signal of an :class:`~servo.scenarios.base.Inputs` over an aligned block of :data:`BLOCK` ticks,
    sample-and-held every ``hold`` ticks (value at tick k = ``signal(k - k % hold)``).

    ``load(k)`` makes the block holding tick ``k`` current and returns k's index in
    :attr:`values`.  A refill (one vectorised call, a few us) happens once per block.
    """

    def __init__(self, signal: Callable[[np.ndarray], np.ndarray], hold: int = 1, size: int = BLOCK):
        self.signal = signal
        self.hold = int(hold)
        self.size = int(size)
        self.values = np.zeros(self.size)
        self.base = -1

    def load(self, k: int) -> int:
        base = k - k % self.size
        if base != self.base:
            ticks = np.arange(base, base + self.size, dtype=np.int64)
            self.values[:] = self.signal(ticks - ticks % self.hold if self.hold > 1 else ticks)
            self.base = base
        return k - base

    def at(self, k: int) -> float:
        """The value at tick ``k``."""
        return float(self.values[self.load(k)])

"""Durations of every tick (compute time, lateness) kept in constant memory.

A loop writes each tick's duration (ns) into :attr:`Durations.buf` and calls
:meth:`Durations.fold` when it is full (every :data:`FOLD_BLOCK` ticks, ~5 us, compiled)
and once at the end: the values go into a histogram with 1 ns bins up to 131 us and 1 %
bins above (:mod:`kernels.histogram`).  Medians and percentiles of tick times are
therefore exact to the nanosecond, and a run of any length needs the same ~1.1 MB.
"""
from __future__ import annotations

import numpy as np

from kernels.histogram import N_BINS, add_durations, lower_edges

FOLD_BLOCK = 4096


class Durations:
    """Per-tick durations (ns): count, first, last, max, histogram, quantiles."""

    def __init__(self, block: int = FOLD_BLOCK):
        self.buf = np.full(block, 0, dtype=np.int64)  # written now (not calloc): no page faults in a loop
        self.counts = np.zeros(N_BINS, dtype=np.int64)
        self.count = 0
        self.first: int | None = None
        self.last: int | None = None
        self.max = 0
        add_durations(self.buf, 0, self.counts)  # compiled (cached) before any loop

    def fold(self, n: int) -> None:
        """Take ``buf[:n]`` into the histogram."""
        if n <= 0:
            return
        v = self.buf[:n]
        if self.first is None:
            self.first = int(v[0])
        self.last = int(v[n - 1])
        self.max = max(self.max, int(v.max()))
        add_durations(self.buf, n, self.counts)
        self.count += n

    def add(self, values: np.ndarray) -> None:
        """Take an array of durations (ns) (for tests and offline use)."""
        values = np.asarray(values, dtype=np.int64)
        for i in range(0, values.size, self.buf.size):
            chunk = values[i : i + self.buf.size]
            self.buf[: chunk.size] = chunk
            self.fold(chunk.size)

    def merge(self, other: "Durations") -> None:
        """Take every duration ``other`` has counted (e.g. the rounds of a benchmark)."""
        other_first = other.first
        if self.first is None:
            self.first = other_first
        if other.count:
            self.last = other.last
        self.max = max(self.max, other.max)
        self.counts += other.counts
        self.count += other.count

    def quantile(self, q: float) -> float:
        """The ``q`` quantile (ns), nearest rank: the smallest duration with at least
        ``q*count`` durations at or below it (the lower edge of its bin above 131 us);
        NaN when empty.  ``q = 1`` is the exact maximum."""
        if self.count == 0:
            return float("nan")
        if q >= 1.0:
            return float(self.max)
        rank = max(int(np.ceil(q * self.count)), 1)
        b = int(np.searchsorted(np.cumsum(self.counts), rank))
        return float(lower_edges()[b])

    def count_above(self, threshold_ns: float) -> int:
        """How many durations exceed ``threshold_ns`` (exact below 131 us)."""
        edges = lower_edges()
        return int(self.counts[edges > threshold_ns].sum())

    def histogram(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower edge in ns, count) of the non-empty bins."""
        nz = np.flatnonzero(self.counts)
        return lower_edges()[nz], self.counts[nz].copy()

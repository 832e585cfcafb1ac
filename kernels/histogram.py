"""Histogram of durations (ns) in constant memory, exact where tick times live.

Bin ``b`` of a duration ``t`` (ns, int64):

* ``t < LINEAR_NS``: bin ``t`` itself (1 ns bins: exact, durations are whole ns);
* above: ``LINEAR_NS + floor(log(t / LINEAR_NS) / log(1 + LOG_STEP))``, bins 1 % wide,
  up to ``MAX_NS`` (longer durations go to the last bin; keep the exact maximum apart).

Negative durations count in bin 0.
"""
import math

import numpy as np
from numba import float64, int64, void

from kernels._cache import kernel

LINEAR_NS = 1 << 17  # 131 us: every tick and lateness of a 50 kHz loop, exactly
LOG_STEP = 0.01
MAX_NS = 10**13  # ~2.8 h
N_BINS = LINEAR_NS + int(math.ceil(math.log(MAX_NS / LINEAR_NS) / math.log1p(LOG_STEP))) + 1
_LOG_BASE = math.log1p(LOG_STEP)


@kernel(int64(int64))
def bin_of(t):
    """The bin of duration ``t`` (ns)."""
    if t < LINEAR_NS:
        return max(t, 0)
    b = LINEAR_NS + int64(math.log(t / LINEAR_NS) / _LOG_BASE)
    return min(b, N_BINS - 1)


@kernel(void(int64[::1], int64, int64[::1]))
def add_durations(values, n, counts):
    """Count ``values[:n]`` (ns) into ``counts`` (:data:`N_BINS`,)."""
    for i in range(n):
        counts[bin_of(values[i])] += 1


@kernel(float64(int64))
def lower_edge(b):
    """The smallest duration (ns) of bin ``b``."""
    if b < LINEAR_NS:
        return float64(b)
    return LINEAR_NS * math.exp((b - LINEAR_NS) * _LOG_BASE)


def lower_edges() -> np.ndarray:
    """Lower edge (ns) of every bin, (:data:`N_BINS`,)."""
    b = np.arange(N_BINS)
    return np.where(b < LINEAR_NS, b, LINEAR_NS * np.exp((b - LINEAR_NS) * _LOG_BASE))

"""Timing helpers: per-sample medians through pytest-benchmark, paired ratios.

* :func:`per_sample_ns`: ``benchmark.pedantic`` over ``rounds`` rounds of a function that
  runs ``n`` samples; the median round time divided by ``n`` (ns).  With benchmarks
  disabled (``--benchmark-disable``) it times the rounds itself, so the budget is still
  asserted.
* :func:`paired` : two functions timed in adjacent pairs (alternating which goes first),
  many short pairs; the median of the per-pair ratios.  Each pair runs under the same
  machine conditions, so a ratio stays meaningful on a loaded host where absolute times
  move by 2x.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np


def per_sample_ns(benchmark, fn, n: int, rounds: int, setup=None) -> float:
    """Median ns per sample of ``fn`` (one call = ``n`` samples) over ``rounds`` rounds.
    ``setup`` (optional) returns the ``(args, kwargs)`` of each round, untimed."""
    benchmark.extra_info["samples_per_round"] = n
    benchmark.pedantic(fn, setup=setup, rounds=rounds, warmup_rounds=1, iterations=1)
    if benchmark.stats is not None:
        median_s = benchmark.stats.stats.median
    else:  # benchmarks disabled: time the rounds here
        ts = []
        for _ in range(rounds):
            args, kwargs = setup() if setup else ((), {})
            t0 = time.perf_counter_ns()
            fn(*args, **kwargs)
            ts.append(time.perf_counter_ns() - t0)
        median_s = float(np.median(ts)) / 1e9
    ns = median_s / n * 1e9
    benchmark.extra_info["ns_per_sample_median"] = ns
    return ns


@dataclass
class Paired:
    """Medians (ns per call) of ``a`` and ``b`` and the median of the ratios a/b."""

    a_ns: float
    b_ns: float
    ratio: float


def paired(a, b, pairs: int = 101) -> Paired:
    """Time ``a()`` and ``b()`` in ``pairs`` adjacent pairs, alternating the order."""
    ta, tb = np.empty(pairs), np.empty(pairs)
    clock = time.perf_counter_ns
    a(), b()  # warm
    for i in range(pairs):
        if i % 2 == 0:
            t0 = clock(); a(); t1 = clock(); b(); t2 = clock()  # noqa: E702
            ta[i], tb[i] = t1 - t0, t2 - t1
        else:
            t0 = clock(); b(); t1 = clock(); a(); t2 = clock()  # noqa: E702
            tb[i], ta[i] = t1 - t0, t2 - t1
    return Paired(float(np.median(ta)), float(np.median(tb)), float(np.median(ta / tb)))

"""Timing helpers: per-sample medians through pytest-benchmark, paired ratios.

* :func:`per_sample_ns`: ``benchmark.pedantic`` over ``rounds`` rounds of a function that
  runs ``n`` samples; the median round time divided by ``n`` (ns).  With benchmarks
  disabled (``--benchmark-disable``) it times the rounds itself, so the budget is still
  asserted.
* :func:`paired` : two functions timed in adjacent pairs (alternating which goes first),
  many short pairs; the median of the per-pair ratios.  Each pair runs under the same
  machine conditions, so a ratio stays meaningful on a loaded host where absolute times
  move by 2x.
* :func:`paired_blocks`: the same for per-call costs of very different sizes: each side
  runs a block of calls sized so that both blocks take the same short time (~250 us,
  far below a scheduler time slice), so a preemption is as likely to land in one block
  as in the other and rarely lands in either.
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


def paired_blocks(a, b, pairs: int = 101, block_ns: float = 250e3, quantum_a: int = 1,
                  quantum_b: int = 1) -> Paired:  # fmt: skip
    """Per-call medians (ns) of ``a(n)`` and ``b(n)`` (each runs ``n`` calls) and the
    median of the per-pair ratios of their per-call times, from ``pairs`` adjacent pairs
    of blocks calibrated to take ``block_ns`` each.  ``quantum_*``: block sizes are
    multiples of this (e.g. the batch of a link, so every block ends on a frame)."""

    def size(fn, quantum: int) -> int:
        n, t = quantum, 0
        while True:  # grow until one block is measurable, then scale to the target
            t0 = time.perf_counter_ns()
            fn(n)
            t = time.perf_counter_ns() - t0
            if t >= block_ns / 4 or n >= 1 << 20:
                break
            n *= 4
        probes = [t]
        for _ in range(4):
            t0 = time.perf_counter_ns()
            fn(n)
            probes.append(time.perf_counter_ns() - t0)
        per_call = float(np.median(probes)) / n
        return max(quantum, int(round(block_ns / per_call / quantum)) * quantum)

    na, nb = size(a, quantum_a), size(b, quantum_b)
    r = paired(lambda: a(na), lambda: b(nb), pairs)
    return Paired(r.a_ns / na, r.b_ns / nb, r.ratio * nb / na)

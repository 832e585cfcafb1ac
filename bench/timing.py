"""Timing helpers: per-sample medians through pytest-benchmark, paired ratios.

* :func:`per_sample_ns`: ``benchmark.pedantic`` over ``rounds`` rounds of a function that
  runs ``n`` samples; the median round's CPU time divided by ``n`` (ns), which a busy
  neighbour does not inflate as it inflates wall time.  With benchmarks disabled
  (``--benchmark-disable``) it times the rounds itself, so the budget is still asserted.
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


def per_sample_ns(benchmark, fn, n: int, rounds: int, setup=None, clock=time.thread_time_ns) -> float:
    """Median ns per sample of ``fn`` (one call = ``n`` samples) over ``rounds`` rounds, in
    CPU time (``clock``: the calling thread's by default; ``time.process_time_ns`` for a
    function whose work runs in threads of its own too).  ``setup`` (optional) returns the
    ``(args, kwargs)`` of each round, untimed.

    CPU time, not wall time: a round of ~10 ms on a host with ten runnable processes per
    core spends most of its wall time waiting for a core (a Dahl update measured 362 ns a
    sample at load 20 against its 200 ns budget and ~60 ns calm), while the CPU time
    counts only what the code costs; on an idle host the two are equal.  The wall-time
    median (pytest-benchmark's) is kept in ``benchmark.extra_info``."""
    benchmark.extra_info["samples_per_round"] = n
    cpu: list[int] = []

    def timed(*args, **kwargs):
        c0 = clock()
        fn(*args, **kwargs)
        cpu.append(clock() - c0)

    benchmark.pedantic(timed, setup=setup, rounds=rounds, warmup_rounds=1, iterations=1)
    if benchmark.stats is not None:
        benchmark.extra_info["wall_ns_per_sample_median"] = benchmark.stats.stats.median / n * 1e9
        cpu = cpu[-rounds:]  # not the warm-up round
    else:  # benchmarks disabled: time the rounds here
        cpu.clear()
        for _ in range(rounds):
            args, kwargs = setup() if setup else ((), {})
            timed(*args, **kwargs)
    ns = float(np.median(cpu)) / n
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

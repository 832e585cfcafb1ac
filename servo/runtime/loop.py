"""The closed loop of a run: the standard tasks, tick by tick or all compiled.

Both paths perform the same operations in the same order (see :mod:`kernels.compose`), so
for the simulated drive they produce the same log, bit for bit:

* before the controller: ``excitation`` every ``run.excitation_every`` ticks (reference
  and excitation values of that tick, held until its next run);
* after the command: ``estimator`` every ``run.estimator_every`` ticks (tracking-error
  statistics, :func:`kernels.compose.error_stats`), then ``log`` every ``run.log_every``
  ticks (one row of the controller's ``log_columns``: :data:`kernels.compose.LOG_COLUMNS`
  then the kind's own).

Nothing compiles or warms up inside the loop: the driver warms its kernels at
``configure``, the controller and the log/estimator kernels are called once on scratch
copies before the first tick, and the garbage collector is disabled
(:func:`servo.runtime.pacing.gc_paused`) from before ``configure`` to the end of the loop, so that
no collection (tens of ms with numba, scipy and matplotlib loaded) lands on a tick.  A pacer, if given, is started right
before the first tick.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from kernels._cache import entry_point
from kernels.compose import LOG_COLUMNS, STATS_SIZE, error_stats
from servo.config import Config
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.driver import Driver, DriverState
from servo.runtime.durations import Durations
from servo.runtime.pacing import Pacer, gc_paused
from servo.runtime.prefetch import Prefetch
from servo.runtime.window import BLOCK, Window
from servo.scenarios import Inputs
from servo.runtime.scheduler import Scheduler, Task
from servo.runtime.simdriver import SimDriver
from servo.runtime.watchdog import Watchdog


@dataclass
class LoopResult:
    """What a closed-loop run measured besides its log.

    ``stats``: error estimator accumulators (sum e^2, count, max |e|); ``timing``:
    per-tick compute times in ns (tick path only, else None); ``wall_s``: loop wall time;
    ``started``: :func:`time.perf_counter` when the loop started; ``link``: what a serial
    driver reports about its link (None for the simulated drive).  A paced run adds
    ``realtime`` (its report, :func:`servo.run.realtime.report`) and ``lateness`` (each
    tick's start behind its deadline, ns).
    """

    n_ticks: int
    fast: bool
    stats: np.ndarray
    timing: Durations | None
    wall_s: float
    started: float = 0.0
    link: dict | None = None
    realtime: dict | None = None
    lateness: Durations | None = None

    @property
    def error_rms(self) -> float:
        """RMS tracking error (m) seen by the estimator task."""
        return float(np.sqrt(self.stats[0] / max(self.stats[1], 1.0)))


def log_rows(cfg: Config) -> int:
    """Rows of the run log of ``cfg``."""
    return -(-cfg.n_ticks // cfg.run.log_every)


def run_closed_loop(
    cfg: Config,
    driver: Driver,
    controller: Controller,
    inputs: Inputs,
    log: RunLog,
    fast: bool = False,
    pacer: Pacer | None = None,
    timing: bool = True,
) -> LoopResult:
    """Run ``cfg.n_ticks`` ticks of ``controller`` against ``driver``.

    Configures the driver if it is not yet, activates it, and deactivates it (safe state)
    on every exit path.  The :class:`~servo.runtime.watchdog.Watchdog` looks at the
    logged rows as they are written and stops an unstable loop
    (:class:`~servo.errors.UnstableLoop`, exit 3), what was recorded kept.  ``fast`` uses the all-compiled loop (simulated drive only); it
    runs a block of ticks per call, so it cannot be paced.
    """
    if fast and not isinstance(driver, SimDriver):
        raise ValueError("the compiled fast path runs against the simulated drive only")
    if driver.closes_loop and pacer is not None:
        raise ValueError("a drive that runs the loop itself is its own clock: it cannot be paced")
    if fast and pacer is not None:
        raise ValueError("the compiled fast path cannot be paced: real-time pacing needs the tick path")
    with gc_paused():
        if driver.state is DriverState.UNCONFIGURED:
            driver.configure()
        stats = np.zeros(STATS_SIZE)
        durations = Durations() if (timing and not fast and not driver.closes_loop) else None
        _warm_up(controller, log)
        watchdog = Watchdog(cfg)
        if not driver.closes_loop:
            driver.activate()
        t0 = time.perf_counter()
        try:
            if driver.closes_loop:  # the loop on the drive: the host supervises and records
                driver.run_loop(cfg, controller, inputs, log, stats, watchdog)
            elif fast:
                _run_fast(cfg, driver, controller, inputs, log, stats, watchdog)
            else:
                _run_ticks(cfg, driver, controller, inputs, log, stats, pacer, durations, watchdog)
            watchdog.look(log)  # the last rows
        finally:
            driver.deactivate()
            if pacer is not None:
                pacer.finish()
            log.flush(wait=False)  # the last rows to the journal's writer; closing the log waits for the disk
        return LoopResult(cfg.n_ticks, fast, stats, durations, time.perf_counter() - t0, started=t0)


def compile_kernels(cfg: Config) -> None:
    """Compile (or load from the cache) every kernel a run of ``cfg`` calls on the host:
    the controller kind's composed kernels, its log row and the estimator, on scratch
    copies.  Call it before a board session opens: a first compile after an install or
    a kernel change takes seconds, longer than a board waits between READY and START."""
    _warm_up(Controller(cfg), None)


def _warm_up(controller, log: RunLog) -> None:
    """First calls of the controller (and its log row) and the estimator, on scratch copies."""
    controller.warm_up()
    error_stats(np.zeros(STATS_SIZE), 0.0)


def _run_ticks(cfg, driver, controller, inputs, log, stats, pacer, durations, watchdog) -> None:
    dt = cfg.dt
    state = controller.stage_state
    log_row = controller.unchecked_log_row  # rows of log.data: 1-D, contiguous, the controller's width
    r, u_exc = Window(inputs.reference), Window(inputs.excitation)
    r.load(0), u_exc.load(0)  # the first windows now, not on the first tick

    sched = Scheduler(driver, controller, pacer=pacer)
    data = sched.data

    def excitation(k: int) -> None:
        data.r = r.at(k)
        data.u_exc = u_exc.at(k)

    def estimator(k: int) -> None:
        error_stats(stats, state[0]["e"])

    look_at = [watchdog.next_look(log)]

    def logger(k: int) -> None:
        log_row(log.data[log.rows], k, dt, data.x, data.u_exc)
        log.rows += 1
        if log.rows >= look_at[0]:
            watchdog.flush(log)  # and the log's block hand-over
            look_at[0] = watchdog.next_look(log)

    sched.before = [Task("excitation", cfg.run.excitation_every, excitation)]
    sched.after = [
        Task("estimator", cfg.run.estimator_every, estimator),
        Task("log", cfg.run.log_every, logger),
    ]
    if pacer is not None:
        pacer.start()
    sched.run(0, cfg.n_ticks, start=True, timing=durations)


#: Ticks per call of the compiled loop at most (eight input blocks, a run log block at
#: one row a tick).  Each return from a call costs the loop's thread ~30 us of CPU on
#: a loaded machine (taking the interpreter lock back from the input and journal
#: threads, the state check, the watchdog's call, caches refilled after the switch):
#: with calls of 1024 ticks the fast path measured 1.35x the C, with these 1.29x
#: (alternated rounds, load 22: docs/studies/2026-11-28-fast-path-at-c.md).  The
#: compiled loop runs the watchdog's tests on each row as it logs it; the state check
#: and the watchdog's verdict come between calls, so a diverging simulation is stopped
#: at the end of the call it diverged in.  A call also ends where the run log's block
#: is full.
CALL_TICKS = 8 * BLOCK


def _fast_inputs(cfg, driver: SimDriver, inputs, k: int, n: int):
    """The inputs of the fast path's calls from tick ``k`` to ``n``: ``(k, m, r, u_exc, d,
    noise)`` for ``m`` ticks, arrays of their own, assembled from the input windows and
    noise blocks of :data:`BLOCK` ticks.  A chunk ends at a multiple of
    :data:`CALL_TICKS`; the first is at most one block (the loop waits for it)."""
    every = cfg.run.excitation_every
    r, u_exc = Window(inputs.reference, every), Window(inputs.excitation, every)
    first = True
    while k < n:
        end = min(k - k % BLOCK + BLOCK if first else k - k % CALL_TICKS + CALL_TICKS, n)
        first = False
        m = end - k
        out_r, out_u, out_d, out_noise = np.empty(m), np.empty(m), np.empty(m), np.empty((m, 2))
        j = k
        while j < end:
            b = min(BLOCK - j % BLOCK, end - j)
            o = j - k
            i = r.load(j)
            out_r[o : o + b] = r.values[i : i + b]
            i = u_exc.load(j)
            out_u[o : o + b] = u_exc.values[i : i + b]
            out_d[o : o + b] = driver.disturbance(j, b)
            out_noise[o : o + b] = driver.noise(j, b)
            j += b
        yield k, m, out_r, out_u, out_d, out_noise
        k = end


#: The compiled loop's entry point per (kernel, log layout), checked once per process.
_ENTRY: dict = {}


def _closed_loop_entry(cfg, driver: SimDriver, controller, stats, log, u_start, watchdog):
    """The compiled loop without Numba's per-call type dispatch (~0.3 us per record array),
    its types checked by a call of no ticks on copies, once per process: the plant's and
    the controller's arrays have the types of their records whatever the run, the log
    block is checked here."""
    data = log.data
    key = (controller.kernels.closed_loop, data.dtype.str, data.ndim, data.flags.c_contiguous)
    fn = _ENTRY.get(key)
    if fn is None:
        p = driver.plant
        none, no_rows = np.zeros(0), np.zeros((0, 2))
        fn = _ENTRY[key] = entry_point(
            controller.kernels.closed_loop, p.state.copy(), p.params, p.q.copy(), p.mab, p.gain, p.ubuf.copy(),
            driver.latency.copy(), controller.buf.copy(), none, none, none, no_rows, driver.tick, 0,
            cfg.run.estimator_every, cfg.run.log_every, stats.copy(), data[:0].copy(), 0, 0, u_start,
            watchdog.watch, watchdog.ring.copy(), watchdog.carry.copy())  # fmt: skip
    return fn


def _run_fast(cfg, driver: SimDriver, controller, inputs, log, stats, watchdog) -> None:
    p = driver.plant
    u_start = driver.applied_current
    first = driver.tick
    closed_loop = _closed_loop_entry(cfg, driver, controller, stats, log, u_start, watchdog)
    est_every, log_every = cfg.run.estimator_every, cfg.run.log_every
    block_rows = getattr(log, "block_rows", log.data.shape[0])
    # the next chunk's inputs are computed while this one runs (the kernel releases the lock)
    with Prefetch(_fast_inputs(cfg, driver, inputs, first, cfg.n_ticks)) as chunks:
        for k, m, r, u_exc, d, noise in chunks:
            i = 0
            while i < m:
                # ticks whose rows fit in what is left of the log's block: a call ends where
                # the block is full, so that the watchdog looks before it is handed over
                n = min(m - i, max(1, block_rows - log.rows) * log_every)
                if n < m:
                    r_, u_, d_, noise_ = r[i : i + n], u_exc[i : i + n], d[i : i + n], noise[i : i + n]
                else:
                    r_, u_, d_, noise_ = r, u_exc, d, noise
                log.rows = closed_loop(
                    p.state, p.params, p.q, p.mab, p.gain, p.ubuf, driver.latency,
                    controller.buf,
                    r_, u_, d_, noise_,
                    k + i, n, est_every, log_every,
                    stats, log.data, log.rows, 1 if k + i == first else 0, u_start,
                    watchdog.watch, watchdog.ring, watchdog.carry,
                )  # fmt: skip
                i += n
                driver.tick = k + i
                driver.check_state()  # after the call's log is kept
                watchdog.flush(log, looked=True)  # the loop tested each row as it logged it


__all__ = ["LOG_COLUMNS", "LoopResult", "log_rows", "run_closed_loop"]

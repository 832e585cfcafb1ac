"""The all-compiled fast path with its logging, against the same closed loop in C with the
same logging (issue 29): ``bench/c/closed_log.c`` runs the loop body of the fast path's
``closed_loop`` (:mod:`kernels.compose`) on the reference's functions and writes the same
log rows to memory.

First that the two log the same bits (a time ratio of different work means nothing), then
the ratio, in adjacent rounds that alternate which goes first (a busy neighbour slows
both of a pair): the fast path as ``servo run --fast`` runs it
(:func:`servo.runtime.loop.run_closed_loop`: the input windows, the sensor noise drawn in
blocks by a thread of their own, the watchdog, the run log journalled to disk by its
writer thread), and the compiled kernel alone on the inputs the C reads, so that what is around the kernel shows
as the difference of the two ratios.
"""
import os
import time

import numpy as np
import pytest

from bench import cref
from bench.budgets import FAST_PATH_OVER_C_MAX
from bench.cloop import CLoggedLoop
from kernels.compose import LOG_COLUMNS, STATS_SIZE
from servo.config import Config
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.loop import run_closed_loop
from servo.runtime.simdriver import SimDriver
from servo.runtime.watchdog import Watchdog
from servo.scenarios import scenario_inputs

#: Round pairs (each side 25 000 ticks, ~15 ms on a calm host).
PAIRS = 41


@pytest.fixture(scope="module")
def clog(tmp_path_factory):
    cc = cref.find_compiler()
    if cc is None:
        pytest.skip("no C compiler on this machine ($CC, cc, gcc, clang): the C closed loop is skipped")
    return CLoggedLoop.load(tmp_path_factory.mktemp("clog"), cc)


class Loop:
    """The default ``servo run`` scenario over ``cfg.n_ticks``, its inputs evaluated for
    the C and the kernel (the fast path evaluates its own, in windows, as it runs)."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.inputs = scenario_inputs(cfg)
        k = np.arange(cfg.n_ticks)
        self.r = np.ascontiguousarray(self.inputs.reference(k), dtype=float)
        self.u_exc = np.ascontiguousarray(self.inputs.excitation(k), dtype=float)
        self.d = np.ascontiguousarray(self.inputs.disturbance(k), dtype=float)
        self.noise = np.random.default_rng(cfg.run.seed).standard_normal((cfg.n_ticks, 2))  # SimDriver's draws
        self.log = np.full((cfg.n_ticks, len(LOG_COLUMNS)), np.nan)  # written now: no page faults in a round

    def started(self):
        """A configured drive and a controller that has taken over at rest."""
        drv = SimDriver(self.cfg, self.inputs)
        drv.configure()
        ctl = Controller(self.cfg)
        ctl.start(0.0, 0.0, drv.plant.u_hold)
        return drv, ctl

    def c(self, lib, drv, ctl, stats, wd):
        r = self.cfg.run
        return lib.run(drv.plant, drv.latency, ctl.records(), self.r, self.u_exc, self.d, self.noise, 0,
                       self.cfg.n_ticks, r.estimator_every, r.log_every, stats, self.log, 0, wd.watch, wd.ring,
                       wd.carry)  # fmt: skip

    def kernel(self, drv, ctl, stats, wd):
        p, r = drv.plant, self.cfg.run
        return ctl.kernels.closed_loop(p.state, p.params, p.q, p.mab, p.gain, p.ubuf, drv.latency, ctl.buf, self.r,
                                       self.u_exc, self.d, self.noise, 0, self.cfg.n_ticks, r.estimator_every,
                                       r.log_every, stats, self.log, 0, 0, 0.0, wd.watch, wd.ring,
                                       wd.carry)  # fmt: skip


def test_c_logs_what_the_fast_path_logs(clog):
    """The C loop and the compiled fast path: the same log rows, estimator, states and
    watchdog's state, to the bit; the watchdog's bounds set low enough (10 um, 2.5 mA) that
    both of its tests find a row, so that each of its branches is compared."""
    cfg = Config().replace(run={"duration_s": 0.3})  # through the first steps of the scenario
    loop = Loop(cfg)
    (da, ca), (db, cb) = loop.started(), loop.started()
    sa, sb = np.zeros(STATS_SIZE), np.zeros(STATS_SIZE)
    wa, wb = Watchdog(cfg), Watchdog(cfg)
    for w in (wa, wb):
        w.watch[:2] = 1e-5, 2.5e-3  # m, A: the arm steps 20 um; |u| is 2.0-2.7 mA on 80 % of the ticks
    assert loop.kernel(da, ca, sa, wa) == cfg.n_ticks
    rows_numba = loop.log.copy()
    assert loop.c(clog, db, cb, sb, wb) == cfg.n_ticks
    assert wa.carry[3] >= 0 and wa.carry[4] >= 0 and 0 < wa.ring.sum() < wa.ring.size
    assert wa.carry.tobytes() == wb.carry.tobytes() and wa.ring.tobytes() == wb.ring.tobytes()
    assert np.ptp(rows_numba[:, LOG_COLUMNS.index("x")]) > 1e-6  # the arm moved
    assert rows_numba.tobytes() == loop.log.tobytes()
    assert sa.tobytes() == sb.tobytes()
    assert da.plant.state.tobytes() == db.plant.state.tobytes() and ca.buf.tobytes() == cb.buf.tobytes()


def test_fast_path_over_c_with_logging(cfg, clog, record, tmp_path):
    """The fast path as a run uses it (run log on disk) over the C loop writing the same rows
    to memory, per sample, paired rounds: at most ``FAST_PATH_OVER_C_MAX``.  Asserted on
    the CPU time of the loop's thread: what the loop itself costs (a busy neighbour does
    not inflate it as it inflates wall time); the journal's writes and the next block's
    inputs run in threads of their own, which the loop does not wait for.  Recorded
    alongside: the other threads' CPU per sample (the journal's writer, the input thread,
    and OpenBLAS's worker threads, which spin for a few ms after each drive's set-up on
    this machine: docs/studies/2026-11-28-fast-path-at-c.md), the ratio of process CPU
    times, of wall times, and the compiled kernel alone over the C."""
    c = cfg.replace(run={"duration_s": 0.5})
    loop = Loop(c)
    logs = []

    def clock():  # CPU time of the loop's thread, of the process (with the journal's writer thread), wall time
        return np.array([time.thread_time_ns(), time.process_time_ns(), time.perf_counter_ns()])

    def fast():
        drv, ctl = SimDriver(c, loop.inputs), Controller(c)
        drv.configure()
        log = RunLog(tmp_path, f"r{len(logs)}", ctl.log_columns)
        logs.append(log)
        t0 = clock()
        run_closed_loop(c, drv, ctl, loop.inputs, log, fast=True)
        t = clock() - t0
        log.close()
        log.npz_path.unlink()
        return t

    def timed(fn, *args):
        drv, ctl = loop.started()
        stats, wd = np.zeros(STATS_SIZE), Watchdog(c)
        t0 = clock()
        fn(*args, drv, ctl, stats, wd)
        return clock() - t0

    sides = {"fast path": fast, "kernel": lambda: timed(loop.kernel), "C": lambda: timed(loop.c, clog)}
    for f in sides.values():
        f()  # warm
    t = {name: np.empty((PAIRS, 3)) for name in sides}
    order = list(sides)
    for i in range(PAIRS):
        for name in order[i % 3 :] + order[: i % 3]:  # rotate which goes first
            t[name][i] = sides[name]()
    n = c.n_ticks
    ratio, process_ratio, wall_ratio = np.median(t["fast path"] / t["C"], axis=0)
    kernel_ratio = float(np.median(t["kernel"][:, 0] / t["C"][:, 0]))
    ns = {name: float(np.median(v[:, 0])) / n for name, v in t.items()}
    others_ns = float(np.median(t["fast path"][:, 1] - t["fast path"][:, 0])) / n
    record.ratio("fast_path_over_c_with_logging", float(ratio), f"<= {FAST_PATH_OVER_C_MAX:g}",
                 fast_path_cpu_ns=ns["fast path"], kernel_cpu_ns=ns["kernel"], c_cpu_ns=ns["C"],
                 kernel_over_c=kernel_ratio, other_threads_cpu_ns=others_ns, process_cpu_ratio=float(process_ratio),
                 wall_ratio=float(wall_ratio), pairs=PAIRS, load=os.getloadavg()[0])  # fmt: skip
    assert ratio <= FAST_PATH_OVER_C_MAX, (
        f"the fast path with its run log takes {ratio:.2f}x the loop-thread CPU time of the C loop with the same logging ({ns['fast path']:.0f} vs "
        f"{ns['C']:.0f} ns per sample; the compiled kernel alone {kernel_ratio:.2f}x)")  # fmt: skip

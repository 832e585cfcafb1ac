"""The two ways a run executes, per sample: tick by tick through the scheduler and the
driver interface (the path real-time runs use), and the all-compiled fast path.

Both run the ``servo run`` scenario through :func:`servo.runtime.loop.run_closed_loop`, with its
standard tasks (excitation, estimator, log) and a run log on disk, as a user runs them.
"""

import time

from bench import workload as w
from bench.budgets import BUDGETS, TICK_PATH_EVERY_TERM_OVER_PAPER_MAX
from bench.timing import per_sample_ns
from kernels.compose import LOG_COLUMNS
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.durations import Durations
from servo.runtime.loop import run_closed_loop
from servo.scenarios import scenario_inputs
from servo.runtime.simdriver import SimDriver

ROUNDS = 9
#: Round pairs of the tick path with every compensator term against the paper's.
PAIRS = 3


class Runs:
    """Fresh driver, controller and log for each round (configured outside the timing)."""

    def __init__(self, cfg, tmp_path, fast):
        self.cfg, self.tmp, self.fast = cfg, tmp_path, fast
        self.inputs = scenario_inputs(cfg)
        self.timing = Durations()  # every round's ticks
        self.open = []

    def setup(self):
        drv = SimDriver(self.cfg, self.inputs)
        drv.configure()
        log = RunLog(self.tmp, f"r{len(self.open)}", LOG_COLUMNS)
        self.open.append((drv, log))
        return (drv, Controller(self.cfg), log), {}

    def run(self, drv, ctl, log):
        res = run_closed_loop(self.cfg, drv, ctl, self.inputs, log, fast=self.fast)
        if res.timing is not None:
            self.timing.merge(res.timing)

    def close(self):
        for drv, log in self.open:
            drv.close()
            log.close()


def test_tick_path_per_tick(benchmark, cfg, record, tmp_path):
    """Read -> controller -> write -> tasks through Scheduler and SimDriver: the median of
    the scheduler's per-tick compute times over all rounds, against 1/4 of the period."""
    c = cfg.replace(run={"duration_s": 0.1})  # 5000 ticks per round
    runs = Runs(c, tmp_path, fast=False)
    try:
        round_ns = per_sample_ns(benchmark, runs.run, c.n_ticks, ROUNDS, setup=runs.setup)
    finally:
        runs.close()
    ticks = runs.timing
    median_us = ticks.quantile(0.5) / 1e3
    benchmark.extra_info["tick_us_median"] = median_us
    record.figure("tick_path", median_us * 1e3, "tick_path", round_ns_per_tick=round_ns,
                  tick_us_p99=ticks.quantile(0.99) / 1e3, ticks=ticks.count)  # fmt: skip
    limit = BUDGETS["tick_path"].ns(cfg) / 1e3
    assert median_us <= limit, f"tick path: {median_us:.2f} us per tick (median), over its budget of {limit:.1f} us (1/4 of the period)"


def test_tick_path_with_every_compensator_term(cfg, record, tmp_path):
    """The tick path with every compensator term on (issue 14), against the paper's
    compensator in rounds that alternate (5000 ticks each): the per-tick median against 1/4
    of the period, as :func:`test_tick_path_per_tick`, and against the paper's path in the
    same rounds (the terms add ~50 ns to a ~4 us tick; the bound, 2x, is a guard against a
    gross regression whatever the load: bench/budgets.py says why it is that wide).
    The share of the period is recorded (``share``)."""
    c = cfg.replace(run={"duration_s": 0.1})
    (tmp_path / "paper").mkdir(), (tmp_path / "every").mkdir()
    runs = {"paper": Runs(c, tmp_path / "paper", fast=False),
            "every term": Runs(c.replace(compensator=w.EVERY_TERM), tmp_path / "every", fast=False)}  # fmt: skip
    try:
        for i in range(2 * PAIRS):
            for name in (("paper", "every term") if i % 2 == 0 else ("every term", "paper")):
                args, _ = runs[name].setup()
                runs[name].run(*args)
    finally:
        for r in runs.values():
            r.close()
    med = {name: r.timing.quantile(0.5) for name, r in runs.items()}
    ratio = med["every term"] / med["paper"]
    share = med["every term"] / (cfg.dt * 1e9)
    record.figure("tick_path_every_term", med["every term"], "tick_path", paper_ns=med["paper"], share_of_period=share,
                  tick_us_p99=runs["every term"].timing.quantile(0.99) / 1e3, ticks=runs["every term"].timing.count)  # fmt: skip
    record.ratio("tick_path_every_term_over_paper", ratio, f"<= {TICK_PATH_EVERY_TERM_OVER_PAPER_MAX:g}",
                 every_term_us=med["every term"] / 1e3, paper_us=med["paper"] / 1e3, share_of_period=share)  # fmt: skip
    limit = BUDGETS["tick_path"].ns(cfg)
    assert med["every term"] <= limit, f"tick path, every compensator term: {med['every term'] / 1e3:.2f} us per tick (median), over {limit / 1e3:.1f} us"
    assert ratio <= TICK_PATH_EVERY_TERM_OVER_PAPER_MAX, (
        f"the compensator terms make the tick path {ratio:.3f}x the paper's ({med['every term'] / 1e3:.2f} vs "
        f"{med['paper'] / 1e3:.2f} us per tick)")  # fmt: skip


def test_fast_path_samples_per_second(benchmark, cfg, record, tmp_path):
    """The all-compiled closed loop (controller + simulated drive + logging), per sample,
    against 1/4 of the period: at least 4x faster than real time."""
    c = cfg.replace(run={"duration_s": 0.5})  # 25000 ticks per round
    runs = Runs(c, tmp_path, fast=True)
    try:
        ns = per_sample_ns(benchmark, runs.run, c.n_ticks, ROUNDS, setup=runs.setup, clock=time.process_time_ns)
    finally:
        runs.close()
    rate = 1e9 / ns
    benchmark.extra_info["samples_per_s"] = rate
    record.figure("fast_path", ns, "fast_path", samples_per_s=rate, real_time_factor=rate / cfg.run.sample_rate_hz)
    limit = BUDGETS["fast_path"].ns(cfg)
    assert ns <= limit, (f"fast path: {ns:.0f} ns per simulated sample ({rate:.3g} samples/s), over its budget of "
                         f"{limit:.0f} ns (1/4 of the period: 4x real time)")  # fmt: skip

"""The tick scheduler: order, multi-rate tasks, bit-identical fast path and reruns."""
import math

import numpy as np
import pytest

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.driver import Driver, DriverInfo
from servo.runtime.loop import log_rows, run_closed_loop
from servo.scenarios import scenario_inputs
from servo.runtime.scheduler import Scheduler, Task
from servo.runtime.simdriver import NOISE_BLOCK, SimDriver


class RecordingDriver(Driver):
    """A fake drive that records every call, to check the order of a tick."""

    def __init__(self, calls):
        super().__init__()
        self.calls = calls
        self.k = 0

    def _on_configure(self):
        return DriverInfo("fake", 1000.0, False, 0, 1.0)

    def _read(self):
        self.calls.append(("read", self.k))
        return float(self.k), math.nan

    def _write(self, u):
        self.calls.append(("write", self.k))
        self.k += 1

    def _on_deactivate(self):
        self.calls.append(("safe", self.k))

    @property
    def applied_current(self):
        return 0.0


class RecordingController:
    def __init__(self, calls):
        self.calls = calls

    def start(self, x, v, u_now):
        self.calls.append(("start", int(x)))

    def tick(self, x, v, r, u_exc):
        self.calls.append(("control", int(x)))
        return 0.0


def test_tick_order_and_multi_rate_tasks():
    calls = []
    drv = RecordingDriver(calls)
    drv.configure()
    drv.activate()

    def task(name):
        return lambda k: calls.append((name, k))

    sched = Scheduler(drv, RecordingController(calls),
                      before=[Task("excite", 2, task("excite")), Task("ref", 3, task("ref"), offset=1)],
                      after=[Task("estimate", 4, task("estimate")), Task("log", 1, task("log"))])  # fmt: skip
    sched.run(0, 7)
    expected = []
    for k in range(7):
        expected.append(("read", k))
        if k == 0:
            expected.append(("start", 0))
        if k % 2 == 0:
            expected.append(("excite", k))
        if (k - 1) % 3 == 0:
            expected.append(("ref", k))
        expected += [("control", k), ("write", k)]
        if k % 4 == 0:
            expected.append(("estimate", k))
        expected.append(("log", k))
    assert calls == expected


def run(cfg: Config, fast: bool, tmp_path, name: str):
    inputs = scenario_inputs(cfg)
    with SimDriver(cfg, inputs) as drv, RunLog(tmp_path, name, LOG_COLUMNS) as log:
        res = run_closed_loop(cfg, drv, Controller(cfg), inputs, log, fast=fast)
    return log.recorded().copy(), res.stats.copy()


@pytest.mark.parametrize(
    "changes",
    [
        {},
        # latency, decimated logging, odd task rates, estimated velocity, runs across noise blocks
        {"link": {"command_latency_ticks": 3},
         "run": {"log_every": 3, "excitation_every": 5, "estimator_every": 7, "duration_s": 0.4},
         "controller": {"velocity_source": "estimated", "direction_deadband": 5e-5},
         "drive": {"Fc": 1e-3, "Fs": 1.5e-3, "cogging": 1e-4, "input_delay_s": 45e-6}},
        # every cancellation term of the compensator beyond eq. (9) on (kernels/cancel.py)
        {"drive": {"Fc": 1e-3, "Fs": 1.5e-3, "fc_asymmetry": 0.2, "b_asymmetry": 0.3, "cogging": 1e-4,
                   "kf_linear": 0.2, "kf_quadratic": -0.1},
         "compensator": {"coulomb_extra": 1e-3, "coulomb_static": 1.5e-3, "coulomb_asymmetry": 0.2, "b_asymmetry": 0.3,
                         "periodic_amplitudes": [1e-4, 2e-5], "periodic_phases": [0.0, 1.0],
                         "kf_linear": 0.2, "kf_quadratic": -0.1}},
        # the same with the authority acting: |u_c| clipped, kf(x) held near 1
        {"drive": {"Fc": 1e-3, "Fs": 1.5e-3, "b_asymmetry": 0.3, "cogging": 1e-4, "kf_linear": 0.2},
         "compensator": {"coulomb_extra": 1e-3, "coulomb_static": 1.5e-3, "b_asymmetry": 0.3, "periodic_amplitudes": [1e-4],
                         "periodic_phases": [0.0], "kf_linear": 0.2, "authority": 3.0e-3, "kf_authority": 1e-4}},
    ],
)  # fmt: skip
def test_fast_path_is_bit_identical_to_the_tick_path(changes, tmp_path):
    cfg = Config().replace(**changes)
    assert cfg.n_ticks > NOISE_BLOCK  # crosses noise blocks
    tick_log, tick_stats = run(cfg, False, tmp_path, "tick")
    fast_log, fast_stats = run(cfg, True, tmp_path, "fast")
    assert tick_log.shape == (log_rows(cfg), len(LOG_COLUMNS))
    assert np.array_equal(tick_log, fast_log)  # bit for bit, not approximately
    assert np.array_equal(tick_stats, fast_stats)
    assert np.ptp(tick_log[:, LOG_COLUMNS.index("x")]) > 1e-6  # something happened
    if cfg.compensator.authority:  # and the bound acted, exactly at its value
        uc = np.abs(tick_log[:, LOG_COLUMNS.index("u_c")])
        assert uc.max() == cfg.compensator.authority and np.mean(uc == cfg.compensator.authority) > 0.01


def test_reruns_are_bit_identical_and_seeds_matter(tmp_path):
    cfg = Config().replace(run={"duration_s": 0.2})
    a, _ = run(cfg, False, tmp_path, "a")
    b, _ = run(cfg, False, tmp_path, "b")
    c, _ = run(cfg.replace(run={"seed": 2}), False, tmp_path, "c")
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_task_period_must_be_positive():
    with pytest.raises(ValueError):
        Task("bad", 0, lambda k: None)


@pytest.mark.parametrize("fast", [True, False])
def test_the_loop_does_not_wait_for_the_journals_last_sync(tmp_path, monkeypatch, fast):
    """The loop hands its last rows to the journal's writer and returns: a disk that takes
    0.5 s per sync costs the loop nothing at its end; closing the log waits for the disk,
    and every row is there."""
    import os
    import time

    import servo.io.runlog as runlog

    real = os.fsync
    monkeypatch.setattr(runlog.os, "fsync", lambda fd: (time.sleep(0.5), real(fd)))
    cfg = Config().replace(run={"duration_s": 0.01})
    inputs = scenario_inputs(cfg)
    with SimDriver(cfg, inputs) as drv:
        log = RunLog(tmp_path, "slow", LOG_COLUMNS)  # its header's sync is before the loop
        res = run_closed_loop(cfg, drv, Controller(cfg), inputs, log, fast=fast, timing=False)
        assert res.wall_s < 0.4
        log.close()
    assert log.recorded().shape[0] == log_rows(cfg)

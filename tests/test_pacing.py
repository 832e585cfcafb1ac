"""Real-time pacing: absolute deadlines, lateness, overrun policy, GC kept out; a paced
closed-loop run computes exactly what the unpaced one does; ``servo run --realtime``."""
import gc
import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.driver import DriverState
from servo.runtime.loop import run_closed_loop
from servo.runtime.pacing import OverrunFault, Pacer, realtime_section
from servo.scenarios import scenario_inputs
from servo.runtime.simdriver import SimDriver


class _RelativePacer(Pacer):
    """The drift the absolute deadlines exist to prevent: each deadline one period after
    the previous tick started, so that every late tick pushes all later ones back."""

    def wait(self, k: int) -> None:
        super().wait(k)
        self.t0 = time.perf_counter_ns() - k * self.period_ns


def _tail_lateness_s(pacer_type, period=200e-6, n=2000) -> tuple[float, dict]:
    """Pace ``n`` ticks with a 150 us stall after every 100th; returns the smallest start
    of a tick behind its absolute deadline (``start + (k+1)*period``) over the last 200
    ticks, and the pacer's report.  A host that preempts the process makes ticks late,
    but whenever it runs again the absolute deadlines are behind it and the ticks run back
    to back until they are on time: the smallest lateness of a stretch is ~0 however loaded
    the host; a drifting pacer carries the 20 stalls, >= 3 ms."""
    p = pacer_type(period, n)
    p.start()
    t0, late = p.t0, np.empty(n)
    for k in range(n):
        p.wait(k)
        late[k] = (time.perf_counter_ns() - (t0 + k * p.period_ns)) / 1e9
        if k % 100 == 0:
            time.sleep(150e-6)  # an occasional long tick: later ticks catch up, no drift
    return float(late[-200:].min()), p.report()


def test_absolute_deadlines_do_not_drift():
    tail, r = _tail_lateness_s(Pacer)
    assert tail < 1e-3, f"the last 200 ticks all started >= {tail * 1e3:.2f} ms behind their deadlines: drift"
    assert r["ticks"] == 2000
    drifting, _ = _tail_lateness_s(_RelativePacer)  # the measure tells drift apart
    assert drifting >= 20 * 150e-6


def test_overruns_are_counted_and_can_fault():
    p = Pacer(100e-6, 100)
    p.start()
    for k in range(10):
        p.wait(k)
        time.sleep(300e-6)  # every tick runs over
    assert p.overruns >= 8
    f = Pacer(100e-6, 100, policy="fault", max_consecutive=3)
    f.start()
    with pytest.raises(OverrunFault, match="3 consecutive deadline overruns"):
        for k in range(10):
            f.wait(k)
            time.sleep(300e-6)


def test_realtime_section_freezes_gc_and_restores():
    assert gc.isenabled()
    with realtime_section(lock_memory=False) as grant:
        assert grant.gc_frozen and not gc.isenabled()
    assert gc.isenabled()


def test_what_the_os_refuses_is_one_note_and_nothing_changes():
    before = os.sched_getaffinity(0)
    with realtime_section(cpu=10**6) as grant:  # no such core
        assert grant.affinity is None and os.sched_getaffinity(0) == before
    assert len(grant.notes) == 1 and grant.notes[0].startswith("CPU affinity to core 1000000: not available")
    assert "\n" not in grant.notes[0]


# ---- pacing a closed-loop run ------------------------------------------------------------


def closed_loop_log(cfg, tmp_path, name, pacer=None):
    inputs = scenario_inputs(cfg)
    with SimDriver(cfg, inputs) as drv, RunLog(tmp_path, name, LOG_COLUMNS) as log:
        res = run_closed_loop(cfg, drv, Controller(cfg), inputs, log, pacer=pacer)
    return log.recorded().copy(), res


def test_pacing_does_not_change_a_single_bit(tmp_path):
    # 0.06 s at 50 kHz: the first reference step (at 0.05 s) is inside the run
    cfg = Config().replace(run={"duration_s": 0.06})
    pacer = Pacer(cfg.dt, cfg.n_ticks)
    paced, _ = closed_loop_log(cfg, tmp_path, "paced", pacer)
    unpaced, _ = closed_loop_log(cfg, tmp_path, "unpaced")
    assert pacer.report()["ticks"] == cfg.n_ticks  # every tick went through the pacer
    assert np.array_equal(paced, unpaced)
    assert np.ptp(paced[:, LOG_COLUMNS.index("x")]) > 1e-7  # the step happened


def test_the_paced_run_keeps_the_sample_rate(tmp_path):
    cfg = Config().replace(run={"duration_s": 0.05})
    pacer = Pacer(cfg.dt, cfg.n_ticks)
    _, res = closed_loop_log(cfg, tmp_path, "paced", pacer)
    # absolute deadlines: the last tick starts at (n-1)*period, however late ticks were
    last = pacer.t0 + (cfg.n_ticks - 1) * pacer.period_ns + pacer.lateness.last
    assert (last - pacer.t0) / 1e9 >= (cfg.n_ticks - 1) * cfg.dt
    assert res.wall_s >= (cfg.n_ticks - 1) * cfg.dt


def test_overrun_fault_leaves_the_drive_at_zero_current_and_keeps_the_log(tmp_path):
    # a 1 MHz sample rate cannot be kept by the Python tick path (~5 us per tick)
    cfg = Config().replace(run={"sample_rate_hz": 1e6, "duration_s": 0.01})
    pacer = Pacer(cfg.dt, cfg.n_ticks, policy="fault", max_consecutive=5)
    inputs = scenario_inputs(cfg)
    with pytest.raises(OverrunFault, match="5 consecutive deadline overruns"):
        with SimDriver(cfg, inputs) as drv, RunLog(tmp_path, "f", LOG_COLUMNS) as log:
            try:
                run_closed_loop(cfg, drv, Controller(cfg), inputs, log, pacer=pacer)
            finally:
                assert drv.state is DriverState.INACTIVE  # deactivated: the safe state
                assert drv.applied_current == 0.0 and not drv.plant.ubuf.any()
    rows = np.load(tmp_path / "f.npz")["tick"]
    # every tick is late at 1 MHz: the 5th overrun in a row (tick 4) faults before it runs
    assert pacer.k_last == 4 and np.array_equal(rows, np.arange(4))


def test_the_fast_path_cannot_be_paced(tmp_path):
    cfg = Config().replace(run={"duration_s": 0.01})
    inputs = scenario_inputs(cfg)
    with SimDriver(cfg, inputs) as drv, RunLog(tmp_path, "x", LOG_COLUMNS) as log:
        with pytest.raises(ValueError, match="cannot be paced"):
            run_closed_loop(cfg, drv, Controller(cfg), inputs, log, fast=True, pacer=Pacer(cfg.dt, cfg.n_ticks))


def servo(*args):
    return subprocess.run([sys.executable, "-m", "servo", *args], capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_servo_run_realtime_reports_lateness_and_matches_the_unpaced_run(tmp_path):
    a, b = tmp_path / "rt", tmp_path / "plain"
    r = servo("run", "--realtime", "--duration", "0.06", "--compensation", "on", "--out", str(a))
    assert r.returncode == 0, r.stderr
    assert "paced in real time" in r.stdout and "lateness (compensated): p50" in r.stdout
    assert "realtime: GC frozen" in r.stdout
    s = json.loads((a / "summary.json").read_text())
    rt = s["runs"]["compensated"]["realtime"]
    assert s["realtime"] is True and rt["ticks"] == 3000
    assert {"lateness_us_p50", "lateness_us_p99", "lateness_us_p999", "lateness_us_max", "overruns"} <= rt.keys()
    assert rt["lateness_us_p50"] <= rt["lateness_us_p99"] <= rt["lateness_us_p999"] <= rt["lateness_us_max"]
    assert (a / "lateness.png").stat().st_size > 10_000
    assert servo("run", "--duration", "0.06", "--compensation", "on", "--out", str(b)).returncode == 0
    la, lb = np.load(a / "log_compensated.npz"), np.load(b / "log_compensated.npz")
    for col in LOG_COLUMNS:
        assert np.array_equal(la[col], lb[col]), col


@pytest.mark.slow
def test_realtime_runs_the_tick_path_even_when_the_config_asks_for_the_fast_path(tmp_path):
    r = servo("run", "--realtime", "--set", "run.fast_path=true", "--duration", "0.01", "--compensation", "off",
              "--out", str(tmp_path / "o"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "tick by tick through the driver interface, paced in real time" in r.stdout
    assert "lateness (uncompensated)" in r.stdout


def test_servo_run_realtime_fault_is_one_line_and_keeps_the_log(tmp_path):
    out = tmp_path / "o"
    r = servo("run", "--realtime", "--overrun-policy", "fault", "--max-overruns", "3", "--set", "run.sample_rate_hz=1e6",
              "--duration", "0.01", "--compensation", "on", "--quiet", "--out", str(out))  # fmt: skip
    assert r.returncode == 3
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.startswith("servo: error: realtime: 3 consecutive deadline overruns")
    assert "drive set to zero current" in r.stderr and f"recorded data kept in {out}.incomplete/" in r.stderr
    kept = tmp_path / "o.incomplete"
    assert (kept / "log_compensated.npz").exists() and not (kept / "summary.json").exists() and not out.exists()


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--cpu", "0"], "--cpu needs --realtime"),
        (["--lock-memory"], "--lock-memory needs --realtime"),
        (["--realtime", "--fast"], "cannot be paced"),
        (["--realtime", "--fifo", "150"], "--fifo priority must be within 1..99"),
        (["--realtime", "--max-overruns", "0"], "--max-overruns must be >= 1"),
        (["--realtime", "--cpu", "4096"], "--cpu 4096: this machine has cores"),
        (["--realtime", "--overrun-policy", "never"], "invalid choice: 'never'"),
        (["--realtime", "--port", "loop://"], "with --port the board is the clock master"),
        (["--fifo", "50", "--port", "loop://"], "--fifo is for pacing the simulated drive"),
    ],
)
def test_servo_run_realtime_bad_options_are_one_line(args, needle, tmp_path):
    r = servo("run", *args, "--duration", "0.01", "--out", str(tmp_path / "o"))
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("servo: error:"), r.stderr
    assert needle in r.stderr
    assert not (tmp_path / "o").exists()

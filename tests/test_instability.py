"""Instability is a fault: the run's watchdog (servo/runtime/watchdog.py) stops a loop that
diverges, saturates for good or leaves its stroke, with exit 3 and one line, on the
simulated drive (tick and fast path) and over the serial link; ``servo loop`` refuses an
unstable design.  The unstable loop is a plug-in PID with kd = 0 (docs/controllers.md):
a PI on the compensated double integrator."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.errors import UnstableLoop
from servo.runtime.closedloop import MemoryLog
from servo.runtime.watchdog import Watchdog

PID = textwrap.dedent('''
    """A PID on the position error, as a plug-in controller kind ("pid")."""
    from dataclasses import dataclass

    import numpy as np
    from numba import float64, from_dtype, njit, void

    from servo.config import P
    from servo.controllers import ControllerKind, register

    STATE = np.dtype([("i", "f8"), ("e_prev", "f8"), ("u0", "f8")])
    PARAMS = np.dtype([("kp", "f8"), ("ki", "f8"), ("kd", "f8"), ("dt", "f8")])
    c_t, p_t = from_dtype(STATE), from_dtype(PARAMS)


    @njit(void(c_t, p_t, float64, float64, float64), cache=True)
    def pid_start(c, p, x, v, u_n):
        c.i = 0.0
        c.e_prev = 0.0
        c.u0 = u_n


    @njit(float64(c_t, p_t, float64, float64, float64, float64, float64, float64, float64), cache=True)
    def pid_tick(c, p, x, v, r_base, r, u_exc, lo, hi):
        e = (r_base + r) - x
        c.i += p.ki * p.dt * e
        d = (e - c.e_prev) / p.dt
        c.e_prev = e
        return min(max(c.u0 + p.kp * e + c.i + p.kd * d + u_exc, lo), hi)


    @njit(void(float64[::1], c_t), cache=True)
    def pid_log(out, c):
        out[0] = c.i


    @dataclass
    class PIDSection:
        """A PID (kind "pid")."""

        kp: float = P(394.8, "A/m", "proportional gain", 0.0)
        ki: float = P(4.961e4, "A/(m*s)", "integral gain", 0.0)
        kd: float = P(0.8796, "A*s/m", "derivative gain", 0.0)


    class PID(ControllerKind):
        name = "pid"
        summary = "PID on the position error"
        Section = PIDSection
        STATE, PARAMS = STATE, PARAMS
        start, tick, log = staticmethod(pid_start), staticmethod(pid_tick), staticmethod(pid_log)
        log_columns, log_units = ("integral",), {"integral": "A"}

        @classmethod
        def params(cls, s, cfg):
            p = np.zeros(1, PARAMS)
            p["kp"], p["ki"], p["kd"], p["dt"] = s.kp, s.ki, s.kd, cfg.dt
            return p

        @classmethod
        def response(cls, s, cfg, f_hz):
            zi = np.exp(-2j * np.pi * np.asarray(f_hz, float) * cfg.dt)
            return s.kp + s.ki * cfg.dt / (1 - zi) + s.kd * (1 - zi) / cfg.dt


    if "pid" not in __import__("servo.controllers", fromlist=["KINDS"]).KINDS:
        register(PID)
''')


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    (tmp_path / "my_pid.py").write_text(PID)
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def servo(cwd, *args):
    return subprocess.run([sys.executable, "-m", "servo", *args], capture_output=True, text=True, cwd=cwd)


def rows(x, u, t0=0.0, dt=2e-5):
    n = len(x)
    out = np.zeros((n, len(LOG_COLUMNS)))
    out[:, LOG_COLUMNS.index("t")] = t0 + dt * np.arange(n)
    out[:, LOG_COLUMNS.index("x")], out[:, LOG_COLUMNS.index("u")] = x, u
    return out


def feed(wd, log, data, chunk=300):
    for i in range(0, len(data), chunk):
        part = data[i : i + chunk]
        log.data[: len(part)] = part
        log.rows = len(part)
        wd.start = 0
        wd.look(log)


def test_the_watchdog_rules():
    cfg = Config()  # stroke 15 mm; limit 1 A; half of any 50 ms window (2500 ticks)
    log = MemoryLog(300)
    n = 20_000
    feed(Watchdog(cfg), log, rows(np.zeros(n), np.where(np.arange(n) % 2 == 0, 1.0, 0.3)))  # 50 %: allowed
    with pytest.raises(UnstableLoop, match=r"sat at its limit .* on 51 % of a 0.05 s window"):
        u = np.where(np.arange(n) % 100 < 51, -1.0, 0.3)  # 51 % at -1 A, spread over every window
        feed(Watchdog(cfg), log, rows(np.zeros(n), u))
    with pytest.raises(UnstableLoop, match=r"position reached 14.25\d* mm at t = 0.38\d* s, outside \+-14.25 mm"):
        feed(Watchdog(cfg), log, rows(np.linspace(0, 15e-3, n), np.zeros(n)))
    with pytest.raises(UnstableLoop, match="position reached nan"):
        feed(Watchdog(cfg), log, rows(np.r_[np.zeros(500), np.nan], np.zeros(501)))
    loose = cfg.replace(run={"fault_limit_share": 1.0, "fault_position": 0.0149})  # (inside the stroke, as it must be)
    feed(Watchdog(loose), log, rows(np.linspace(0, 14.8e-3, n), np.ones(n)))  # both rules off


@pytest.mark.slow
@pytest.mark.parametrize("fast", ["--fast", "--no-fast"])
def test_an_unstable_plugin_stops_servo_run_with_exit_3(plugin, fast):
    out = plugin / f"run{fast}"
    r = servo(plugin, "run", "--plugin", "my_pid", "--set", "controller.kind=pid", "--set", "controller.pid.kd=0",
              "--compensation", "on", "--log-format", "npz", fast, "--out", str(out), "--quiet")  # fmt: skip
    assert r.returncode == 3 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.startswith("servo: error: unstable loop:"), r.stderr
    assert "overshoot" not in r.stdout  # no normal summary
    # the stable PID (kd > 0) runs to the end
    r = servo(plugin, "run", "--plugin", "my_pid", "--set", "controller.kind=pid", "--compensation", "on",
              "--duration", "0.2", "--log-format", "npz", fast, "--out", str(plugin / f"ok{fast}"), "--quiet")  # fmt: skip
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_an_unstable_plugin_stops_over_the_serial_link(plugin, tmp_path):
    sys.modules.pop("my_pid", None)  # an earlier test may have imported (and unregistered) it
    import my_pid  # noqa: F401  (registers "pid" in this process)
    from hil.emulator import Board, start_in_thread
    from hil.serialdriver import SerialDriver
    from servo.controllers import KINDS
    from servo.io.runlog import RunLog
    from servo.runtime.controller import Controller
    from servo.runtime.loop import run_closed_loop
    from servo.scenarios import scenario_inputs

    try:
        cfg = Config().replace(controller={"kind": "pid", "pid": {"kd": 0.0}}, run={"duration_s": 0.3},
                               link={"watchdog_s": 2.0, "timeout_s": 2.0})  # fmt: skip
        board = Board(cfg)
        with start_in_thread(board, "tcp") as url:
            ctl = Controller(cfg, compensation=True)
            with pytest.raises(UnstableLoop, match="unstable loop"):
                with SerialDriver(cfg, url) as drv, RunLog(tmp_path, "hil", ctl.log_columns) as log:
                    run_closed_loop(cfg, drv, ctl, scenario_inputs(cfg), log)
            kept = log.total + log.rows
            assert 0 < kept < cfg.n_ticks  # stopped early, what was recorded kept
            assert board.applied_current == 0.0  # the board at its safe state
    finally:
        KINDS.pop("pid", None)


@pytest.mark.slow
def test_servo_loop_refuses_an_unstable_design(plugin):
    out = plugin / "loop"
    r = servo(plugin, "loop", "--plugin", "my_pid", "--set", "controller.kind=pid", "--set", "controller.pid.kd=0",
              "--compensator", "on", "--out", str(out), "--quiet")  # fmt: skip
    assert r.returncode == 3 and r.stderr.count("\n") == 1, r.stderr
    assert "designed closed loop" in r.stderr and "is unstable" in r.stderr and "no margins" in r.stderr
    assert not out.exists() and not (plugin / "loop.incomplete").exists()

"""The in-memory closed loop: the all-compiled fast path, logged in memory.

Experiments, loop measurements, fleets and studies run many short simulations (a Bode sweep
runs one per frequency and level); they need the log as arrays, not as files.
:class:`MemoryLog` has the interface
:func:`servo.runtime.loop.run_closed_loop` uses (``data``, ``rows``, ``maybe_flush``,
``flush``) and keeps everything in memory.
"""
from __future__ import annotations

import math

import numpy as np

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.errors import ConfigError
from servo.runtime.controller import Controller
from servo.runtime.loop import log_rows, run_closed_loop
from servo.scenarios import ArrayInputs
from servo.runtime.simdriver import SimDriver


#: Most rows an in-memory log may hold (every tick of an experiment: 168 s at 50 kHz;
#: with the ~12-20 columns of a log, 0.8-1.3 GB).  Checked before its inputs or its log
#: are allocated (``--duration 1e9`` asked for 364 TiB, exit 70).
MAX_MEMORY_ROWS = 1 << 23


def simulation_ticks(duration_s: float, dt: float, what: str = "--duration") -> int:
    """The ticks of a simulated experiment ``duration_s`` long at period ``dt`` s: a
    :class:`~servo.errors.ConfigError` naming ``what`` unless finite, positive and at
    most :data:`MAX_MEMORY_ROWS` ticks."""
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ConfigError(f"{what} = {duration_s!r} s: expected a positive, finite duration")
    n = round(duration_s / dt)
    if not 1 <= n <= MAX_MEMORY_ROWS:
        raise ConfigError(f"{what} = {duration_s:g} s is {n} ticks at {1 / dt:g} Hz, outside the 1 to {MAX_MEMORY_ROWS} "
                          f"an in-memory simulation may hold ({MAX_MEMORY_ROWS * dt:g} s)")  # fmt: skip
    return int(n)


class MemoryLog:
    """A run log that stays in memory: rows of ``columns`` (a controller's
    ``log_columns``; :data:`kernels.compose.LOG_COLUMNS` then the kind's own), at most
    :data:`MAX_MEMORY_ROWS`."""

    def __init__(self, n_rows: int, columns: tuple[str, ...] = LOG_COLUMNS):
        if n_rows > MAX_MEMORY_ROWS:
            raise ConfigError(f"an in-memory run of {n_rows} log rows, more than the {MAX_MEMORY_ROWS} it may hold: "
                              "a shorter run, a larger run.log_every, or servo run with its logs on disk")  # fmt: skip
        self.columns = tuple(columns)
        self.data = np.full((n_rows, len(self.columns)), np.nan)
        self.rows = 0

    def maybe_flush(self) -> None:
        pass

    def flush(self, wait: bool = True) -> None:
        pass

    def as_dict(self) -> dict[str, np.ndarray]:
        """Column name -> (rows,) array of what was recorded."""
        d = self.data[: self.rows]
        return {c: d[:, i].copy() for i, c in enumerate(self.columns)}


def simulate(cfg: Config, u_exc: np.ndarray, r: np.ndarray | None = None, compensation: bool = False,
             d: np.ndarray | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """Run ``len(u_exc)`` ticks of the closed loop on the simulated drive of ``cfg``.

    ``u_exc``: excitation current (A) added to the holding loop's output, one per tick;
    ``r``: reference (m, from the holding position; default 0); ``d``: force disturbance
    (A).  Returns the log columns (``t``, ``x``, ``v``, ``u``, ``u_c``, ...) as arrays.
    """
    n = int(len(u_exc))
    cfg = cfg.replace(run={"duration_s": n * cfg.dt, "log_every": 1})
    if cfg.n_ticks != n:  # rounding of duration_s * rate
        raise ValueError(f"tick count mismatch: {cfg.n_ticks} != {n}")
    return run_in_memory(cfg, ArrayInputs(r=r, u_exc=u_exc, d=d), compensation).as_dict()


def run_in_memory(cfg: Config, inputs, compensation: bool | None = None) -> MemoryLog:
    """The closed loop of ``cfg`` on its simulated drive under ``inputs`` (a scenario's
    inputs), all compiled, logged in memory; ``compensation`` overrides the config's."""
    controller = Controller(cfg, compensation=compensation)
    log = MemoryLog(log_rows(cfg), controller.log_columns)
    driver = SimDriver(cfg, inputs)
    try:
        run_closed_loop(cfg, driver, controller, inputs, log, fast=True, timing=False)
    finally:
        driver.close()
    return log


__all__ = ["MAX_MEMORY_ROWS", "MemoryLog", "run_in_memory", "simulate", "simulation_ticks"]

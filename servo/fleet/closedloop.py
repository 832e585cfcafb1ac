"""One drive's ``servo run`` scenario on the all-compiled fast path, in memory, and its figures.

The same closed loop as ``servo run --fast`` (:func:`servo.runtime.loop.run_closed_loop`
with a :class:`~servo.runtime.simdriver.SimDriver` and the PI holding loop of
:class:`~servo.runtime.controller.Controller`), but the log stays in memory
(:class:`servo.experiments.sim.MemoryLog`): no journal, no NPZ or CSV per drive.  The
figures are those of ``servo run``'s summary, from :mod:`servo.run.metrics`: tracking
error RMS over the run and per scenario segment, overshoot and settling of every
reference step.
"""
from __future__ import annotations

import numpy as np

from kernels.loop import LOG_COLUMNS
from servo.config import Config
from servo.experiments.sim import MemoryLog
from servo.run.metrics import rms, step_metrics
from servo.runtime.controller import Controller
from servo.runtime.loop import log_rows, run_closed_loop
from servo.runtime.scenario import scenario_inputs, segments
from servo.runtime.simdriver import SimDriver

COL = {c: i for i, c in enumerate(LOG_COLUMNS)}


def run_scenario(cfg: Config, compensated: bool) -> np.ndarray:
    """The log rows (rows, len(LOG_COLUMNS)) of the scenario of ``cfg`` on its simulated
    drive, with or without the compensator.  A simulation whose state stops being finite
    raises :class:`~servo.errors.DriverError`."""
    inputs = scenario_inputs(cfg)
    log = MemoryLog(log_rows(cfg))
    driver = SimDriver(cfg, inputs.d)
    try:
        run_closed_loop(cfg, driver, Controller(cfg, compensation=compensated), inputs, log, fast=True, timing=False)
    finally:
        driver.close()
    return log.data[: log.rows]


def _slug(name: str) -> str:
    return name.replace(" ", "")


def figures(cfg: Config, log: np.ndarray) -> dict:
    """Flat figures of one run's log: ``error_rms_m``, ``error_max_m``, ``rms_<segment>_m``
    (``hold``, ``step1``..., ``disturbance``), and per step ``i`` that changes the
    reference ``step<i>_overshoot_pct`` and ``step<i>_settling_ms`` (None: not settled
    within its segment)."""
    t, x, e = log[:, COL["t"]], log[:, COL["x"]], log[:, COL["e"]]
    segs = segments(cfg)
    out = {"error_rms_m": rms(e), "error_max_m": float(np.abs(e).max())}
    for name, a, b in segs:
        out[f"rms_{_slug(name)}_m"] = rms(e[(t >= a) & (t < b)])
    ends = {name: b for name, _, b in segs}
    x_hold, prev = log[0, COL["r"]], 0.0
    for i, (ts, pos) in enumerate(zip(cfg.scenario.step_times, cfg.scenario.step_positions), 1):
        if ts < cfg.run.duration_s and pos != prev:
            m = step_metrics(t, x, ts, ends[f"step {i}"], x_hold + prev, x_hold + pos)
            out[f"step{i}_overshoot_pct"] = m["overshoot_pct"]
            out[f"step{i}_settling_ms"] = m["settling_ms"]
        prev = pos
    return out


def compare(cfg: Config) -> dict:
    """Figures with the compensator (``comp_*``) and without (``uncomp_*``) for the drive
    of ``cfg`` (the compensator's own settings are those of ``cfg.compensator``)."""
    out = {}
    for label, on in (("comp", True), ("uncomp", False)):
        out.update({f"{label}_{k}": v for k, v in figures(cfg, run_scenario(cfg, on)).items()})
    return out


__all__ = ["compare", "figures", "run_scenario"]

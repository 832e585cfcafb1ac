"""One drive's ``servo run`` scenario on the all-compiled fast path, in memory, and its figures.

The same closed loop as ``servo run --fast``
(:func:`servo.runtime.closedloop.run_in_memory`: the simulated drive and the config's
controller, all compiled), but the log stays in memory: no journal, no NPZ or CSV per
drive.  The figures are those of ``servo run``'s summary, from :mod:`servo.run.metrics`: tracking
error RMS over the run and per scenario segment, overshoot and settling of every
reference step (:class:`servo.run.reduce.RunFigures`).
"""
from __future__ import annotations

import numpy as np

from servo.config import Config
from servo.runtime.closedloop import run_in_memory
from servo.run.reduce import RunFigures
from servo.scenarios import scenario_inputs


def run_scenario(cfg: Config, compensated: bool) -> np.ndarray:
    """The log rows (rows, len(LOG_COLUMNS)) of the scenario of ``cfg`` on its simulated
    drive, with or without the compensator (:func:`servo.runtime.closedloop.run_in_memory`).
    A simulation whose state stops being finite raises :class:`~servo.errors.DriverError`."""
    log = run_in_memory(cfg, scenario_inputs(cfg), compensation=compensated)
    return log.data[: log.rows]


def _slug(name: str) -> str:
    return name.replace(" ", "")


def figures(cfg: Config, log: np.ndarray) -> dict:
    """Flat figures of one run's log, computed as ``servo run``'s summary computes them
    (:class:`servo.run.reduce.RunFigures`): ``error_rms_m``, ``error_max_m``,
    ``rms_<segment>_m`` (``hold``, ``step1``..., ``disturbance``), and per step ``i`` that
    changes the reference ``step<i>_overshoot_pct`` and ``step<i>_settling_ms`` (None: not
    settled within its segment)."""
    reduce = RunFigures(cfg)
    reduce(log)
    f = reduce.result()
    out = {"error_rms_m": f["error_rms_m"], "error_max_m": f["error_max_m"]}
    out.update({f"rms_{_slug(name)}_m": v for name, v in f["error_rms_by_segment_m"].items()})
    steps = {ts: st for ts, st in zip(cfg.scenario.step_times, range(1, len(cfg.scenario.step_times) + 1))}
    for st in f["steps"]:
        i = steps[st["t_s"]]
        out[f"step{i}_overshoot_pct"] = st["overshoot_pct"]
        out[f"step{i}_settling_ms"] = st["settling_ms"]
    return out


def compare(cfg: Config) -> dict:
    """Figures with the compensator (``comp_*``) and without (``uncomp_*``) for the drive
    of ``cfg`` (the compensator's own settings are those of ``cfg.compensator``)."""
    out = {}
    for label, on in (("comp", True), ("uncomp", False)):
        out.update({f"{label}_{k}": v for k, v in figures(cfg, run_scenario(cfg, on)).items()})
    return out


__all__ = ["compare", "figures", "run_scenario"]

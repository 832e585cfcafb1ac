"""``servo fleet simulate``: one drawn drive's closed loop, compensator on and off, as one row.

The payload is the drive's drawn ``[drive]`` fields; the settings carry the rest of the
configuration (the base config as a document: the compensator keeps its own settings,
so the fleet shows how one compensator tuned for the nominal drive does across the
spread).  The row: the drawn fields as ``drive.<field>`` and the figures of
:func:`servo.fleet.closedloop.compare` (``comp_*``, ``uncomp_*``).
"""
from __future__ import annotations

import hashlib

from servo.config import from_dict
from servo.fleet.task import Task, canonical, code_versions, task_key

#: drives per Dask task (a drive's two runs take a few tens of milliseconds)
BATCH = 16
#: what a worker imports as it joins (the closed loop's kernels; the client needs none)
WARM = ("servo.fleet.closedloop",)
#: the fewest drives a default local cluster is started for (fewer run in this process):
#: a drive takes ~35 ms idle, a cluster 4-8 s to start, so two workers save that from ~250
CLUSTER_MIN = 256


def settings(base: dict, vary: dict, seed: int, plugins: list[str] | None = None) -> dict:
    """The settings of a Monte Carlo fleet: the base config document
    (:func:`servo.config.to_dict`), the distributions' texts and the seed (JSON-able;
    part of the resume key; the fleet's size is not, so a larger fleet of the same
    seed resumes the drives of a smaller one); ``plugins``, the modules of controller
    kinds the workers load (``--plugin``)."""
    out = {"command": "simulate", "base": base, "vary": dict(vary), "seed": int(seed)}
    if plugins:
        out["plugins"] = list(plugins)
    return out


def drive_tasks(drives: list[dict], s: dict) -> list[Task]:
    """One task per drawn drive, named ``drive-00000``...; its content hash is that of
    its drawn fields."""
    width = max(5, len(str(len(drives) - 1)))
    versions = code_versions()
    out = []
    for i, d in enumerate(drives):
        h = hashlib.sha256(canonical(d).encode()).hexdigest()
        out.append(Task(f"drive-{i:0{width}d}", task_key(h, s, versions=versions), f"simulated:{s['seed']}:{i}", h, d))
    return out


def config_of(drive: dict, s: dict):
    """The validated config of one drive: the base with its drawn fields."""
    from servo.controllers.plugins import load_plugins  # the kinds' kernels: in the worker, not the client

    load_plugins(s.get("plugins"))  # a worker knows the plugin kinds the client loaded
    data = {k: dict(v) for k, v in s["base"].items()}
    data["drive"].update(drive)
    return from_dict(data)


def run(drive: dict, s: dict) -> dict:
    """Columns of one drive (``{field: value}``)."""
    from servo.fleet.closedloop import compare  # the kernels: loaded by the worker, not the client

    out = {f"drive.{k}": float(v) for k, v in drive.items()}
    out.update(compare(config_of(drive, s)))
    return out


def figures(columns: list[str]) -> list[str]:
    """Columns plotted as histograms and summarised in the report: the main figures of
    both runs, tracking error RMS, each step's overshoot and settling, the disturbance
    segment's RMS (not the drawn fields: they are what was asked for)."""
    ends = ("_error_rms_m", "_overshoot_pct", "_settling_ms", "_rms_disturbance_m")
    return [c for c in columns if c.startswith(("comp_", "uncomp_")) and c.endswith(ends)]


def scored(columns: list[str]) -> list[str]:
    """Columns scored for outliers: the continuous figures of :func:`figures`, the RMS
    errors (a step's overshoot and settling time are quantised, by the position
    sensor's quantum and the sample period, and jump when a peak crosses the band)."""
    return [c for c in figures(columns) if c.endswith(("_error_rms_m", "_rms_disturbance_m"))]


def pairs(columns: list[str]) -> list[tuple[str, str]]:
    """The main pairs to scatter: each drawn field against the compensated run's error,
    and settling with against without the compensator for each step."""
    out = [(c, "comp_error_rms_m") for c in columns if c.startswith("drive.") and "comp_error_rms_m" in columns]
    for c in columns:
        if c.startswith("uncomp_step") and c.endswith("_settling_ms") and c[2:] in columns:
            out.append((c, c[2:]))
    return out


__all__ = ["BATCH", "CLUSTER_MIN", "WARM", "config_of", "drive_tasks", "figures", "pairs", "run", "scored", "settings"]

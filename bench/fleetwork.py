"""The fleet benchmark's workload (``bench/test_fleet.py``), importable by Dask workers
and by the serial process.

:func:`fleet`: a Monte Carlo fleet of ``servo fleet simulate`` (drives drawn from
distributions, each run through the ``servo run`` scenario twice, compensator on and
off).  :func:`timed_batch`: the fleet's batch function (:func:`servo.fleet.task.run_batch`)
with, in each row, its share of the batch's wall time and of the CPU time of the thread
that ran it, and the process it ran in.  :func:`serial`: the whole fleet through the
fleet's in-process path, timed inside the process that runs it.

This module imports numpy only inside its functions: a process started for the serial
run gets its thread settings from its environment before numpy loads.
"""
from __future__ import annotations

import os
import time
from functools import partial

#: what varies across the fleet (the ``servo fleet simulate --vary`` specs of docs/fleet.md, "Measured")
VARY = {"drive.Ha": "lognormal(1e-3, 20%)", "drive.sigma": "normal(320, 10%)", "drive.B": "normal(2e-3, 10%)"}
#: the keys :func:`timed_batch` adds to a row
TIMING = ("_wall_s", "_cpu_s", "_pid")


def fleet(n: int, duration_s: float = 0.6, seed: int = 0) -> tuple[list, dict]:
    """The tasks and settings of an ``n``-drive Monte Carlo fleet (the default config,
    ``duration_s`` of scenario)."""
    from servo.config import Config, to_dict
    from servo.fleet import simulate
    from servo.fleet.spec import draw_drives, parse_specs

    cfg = Config().replace(run={"duration_s": duration_s})
    dists = parse_specs(VARY)
    s = simulate.settings(to_dict(cfg), {d.key: d.text for d in dists}, seed)
    return simulate.drive_tasks(draw_drives(dists, n, seed), s), s


def timed_batch(command: str, settings: dict, tasks: list) -> list[dict]:
    """:func:`servo.fleet.task.run_batch`, each row with its share of the batch's wall and
    thread-CPU seconds (``_wall_s``, ``_cpu_s``) and the ``_pid`` that ran it."""
    from servo.fleet.task import run_batch

    w0, c0 = time.perf_counter(), time.thread_time()
    rows = run_batch(command, tasks, settings)
    wall, cpu = time.perf_counter() - w0, time.thread_time() - c0
    for r in rows:
        r.update(_wall_s=wall / len(rows), _cpu_s=cpu / len(rows), _pid=os.getpid())
    return rows


def batch_fn(settings: dict):
    """The function of a batch that the runner ships to the workers."""
    return partial(timed_batch, "simulate", settings)


def warm(n: int = 2) -> int:
    """Import servo and run ``n`` drives (the kernels load from Numba's cache): the first
    task of a fresh process costs seconds that are not the fleet's."""
    tasks, s = fleet(n)
    timed_batch("simulate", s, tasks)
    return os.getpid()


def process_cpu_s() -> float:
    """CPU seconds of this whole process so far, every thread (run on each worker with
    ``client.run``: a worker's communication and heartbeats besides its batches)."""
    return time.process_time()


def serial(n: int, duration_s: float = 0.6) -> tuple[float, list[dict]]:
    """The whole fleet through the runner's in-process path (``--workers 0``), in this
    process: (wall seconds, rows)."""
    from servo.fleet.runner import Where, map_batches

    tasks, s = fleet(n, duration_s)
    t0 = time.perf_counter()
    rows = map_batches(batch_fn(s), tasks, Where(workers=0))
    return time.perf_counter() - t0, rows

"""Benchmark: a fleet on Dask, serial vs one worker vs two workers, and the scheduler's
overhead (issue 13).

The same Monte Carlo fleet (:data:`DRIVES` drives of ``servo fleet simulate``, each
through the 0.6 s ``servo run`` scenario with the compensator on and off,
:mod:`bench.fleetwork`) runs three ways, in :data:`ROUNDS` rounds whose order rotates,
so that all three see the same machine:

* **serial**: the fleet's in-process path (``--workers 0``,
  :func:`servo.fleet.runner.map_batches`), in a process of its own started with the
  thread settings Dask gives its workers (one BLAS/OpenMP thread).  The comparison is
  then of Dask, not of BLAS threads: in a process with the default threads, the small
  matrix exponentials of the simulated drive's setup (``scipy.linalg.expm``) ran up to
  10x slower while other processes loaded the machine;
* **one worker**, **two workers**: local clusters (``distributed.LocalCluster``, one
  thread per worker process) started and warmed (servo imported, the kernels loaded from
  Numba's cache) before the rounds; the fleet goes through the runner's path on a
  connected client, batched as ``servo fleet`` batches it.

Each batch records its wall time and the CPU time of the thread that ran it.  What is
asserted depends on the scheduling, which is Dask's (and ours), not on how much CPU the
machine leaves the workers, which is the neighbours': each bound holds on this 2-core
machine with another busy process (``python -m bench.load 1 -- python -m pytest
bench/test_fleet.py``) and with the machine shared by several test suites (load 5-9).
On the medians over the rounds:

* **two workers vs one**: the work-seconds the two workers did per second of wall,
  over one worker's, ``2 * busy_two / busy_one`` >= :data:`SCALING_MIN` (1.7): Dask
  keeps both workers busy with the fleet (no idle worker, no long tail, little
  overhead), which on an idle 2-core machine is the issue's "two workers at least 1.7x
  one" in wall time;
* and in wall time, normalised by the CPU the workers obtained while running (the sum
  of each worker's CPU/wall rate in its batches): ``(t_one / t_two) / (cpu_two /
  cpu_one)`` >= :data:`EFFICIENCY_MIN`.  With one other busy process three runnable
  processes share two cores: two workers can then be only ~1.33x one in wall time,
  which this accepts, while a worker left idle would fail it;
* **scheduler overhead**: with one worker, (wall - the time the worker spent in the
  batches) / (the time in the batches) < :data:`OVERHEAD_MAX` (5 %): submitting,
  scheduling, shipping the rows back and gathering them in order;
* the three tables are equal, row for row.

The wall times, two workers / one worker and one worker / serial in wall time are
recorded (``bench/results/latest.json``, check ``fleet_scaling``) and, measured,
in ``bench/README.md``; they are not asserted: a neighbour starting or stopping between
two runs moves them by 2x.  So is starting the clusters (seconds, paid once per
command).  ``python -m pytest bench/test_fleet.py -s`` prints the figures.
"""
import multiprocessing as mp
import os
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

import numpy as np
import pytest

from bench import fleetwork

DRIVES = 48
ROUNDS = 3
SCALING_MIN = 1.7
EFFICIENCY_MIN = 0.75
"""Measured 0.84-0.94 (medians of 3 rounds; single rounds 0.78-1.2) with the machine shared at load 5-12."""
OVERHEAD_MAX = 0.05


@contextmanager
def _environ(**env):
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _worker_environ() -> dict:
    """The environment Dask's nanny gives a worker process (one BLAS/OpenMP thread...)."""
    import dask

    return {k: str(v) for k, v in (dask.config.get("distributed.nanny.pre-spawn-environ") or {}).items()}


@pytest.fixture(scope="module")
def places():
    """The serial process and the two clusters, started and warmed; their start times."""
    from distributed import Client, LocalCluster

    started = {}
    with _environ(**_worker_environ()):
        serial = ProcessPoolExecutor(1, mp_context=mp.get_context("spawn"))
        t0 = time.perf_counter()
        serial.submit(fleetwork.warm).result()
        started["serial_process_s"] = time.perf_counter() - t0
    clients, clusters = {}, []
    for n in (1, 2):
        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
        pids = set(client.run(fleetwork.warm).values())
        assert len(pids) == n
        started[f"cluster_{n}_workers_s"] = time.perf_counter() - t0
        clients[n] = client
        clusters.append(cluster)
    try:
        yield serial, clients, started
    finally:
        serial.shutdown()
        for c in clients.values():
            c.close()
        for c in clusters:
            c.close()


def _strip(rows):
    return [{k: v for k, v in r.items() if k not in fleetwork.TIMING} for r in rows]


def _capacity(rows) -> float:
    """The CPU the workers obtained while running: the sum over worker processes of their
    CPU / wall in the batches (1 per worker on an idle machine)."""
    by = {}
    for r in rows:
        w, c = by.get(r["_pid"], (0.0, 0.0))
        by[r["_pid"]] = (w + r["_wall_s"], c + r["_cpu_s"])
    return sum(c / w for w, c in by.values())


def test_two_workers_scale_and_the_scheduler_costs_little(places, record):
    from servo.fleet.runner import Where, map_batches
    from servo.fleet.simulate import BATCH

    serial, clients, started = places
    tasks, s = fleetwork.fleet(DRIVES)
    fn = fleetwork.batch_fn(s)

    def on(n):
        t0 = time.perf_counter()
        rows = map_batches(fn, tasks, Where(), BATCH, client=clients[n])
        return time.perf_counter() - t0, rows

    runs = {"serial": lambda: serial.submit(fleetwork.serial, DRIVES).result(), "one": lambda: on(1),
            "two": lambda: on(2)}  # fmt: skip
    names = list(runs)
    per_round = []
    reference = None
    for i in range(ROUNDS):
        got = {}
        for name in names[i % 3 :] + names[: i % 3]:  # the order rotates
            got[name] = runs[name]()
        for name, (_, rows) in got.items():
            assert all(r["status"] == "ok" for r in rows), name
            reference = reference or _strip(rows)
            assert _strip(rows) == reference, f"{name}: a table differs"
        (ts, rs), (t1, r1), (t2, r2) = got["serial"], got["one"], got["two"]
        busy = {k: sum(r["_wall_s"] for r in rows) for k, (_, rows) in got.items()}
        cap = {k: _capacity(rows) for k, (_, rows) in got.items()}
        per_round.append({
            "serial_s": ts, "one_s": t1, "two_s": t2, "speedup": t1 / t2, "cpu_ratio": cap["two"] / cap["one"],
            "efficiency": (t1 / t2) / (cap["two"] / cap["one"]), "overhead": (t1 - busy["one"]) / busy["one"],
            "busy_one": busy["one"] / t1, "busy_two": busy["two"] / (2 * t2), "one_over_serial": t1 / ts,
            "one_over_serial_cpu": (t1 * cap["one"]) / (ts * cap["serial"]),
            "work_cpu_s": sum(r["_cpu_s"] for r in r1), "serial_cpu_s": sum(r["_cpu_s"] for r in rs),
        })  # fmt: skip
    med = {k: float(np.median([r[k] for r in per_round])) for k in per_round[0]}
    scaling = 2 * med["busy_two"] / med["busy_one"]
    record.check("fleet_scaling", drives=DRIVES, rounds=ROUNDS, medians=med, scaling=scaling, per_round=per_round,
                 started=started, bounds={"scaling_min": SCALING_MIN, "efficiency_min": EFFICIENCY_MIN,
                                          "overhead_max": OVERHEAD_MAX})  # fmt: skip
    record.ratio("fleet_two_over_one_worker_busy", scaling, f">= {SCALING_MIN}", wall_ratio=med["speedup"],
                 cpu_ratio=med["cpu_ratio"], efficiency=med["efficiency"])  # fmt: skip
    record.ratio("fleet_scheduler_overhead", med["overhead"], f"< {OVERHEAD_MAX}")
    print(f"\nfleet of {DRIVES} drives, medians of {ROUNDS} rounds: serial {med['serial_s']:.2f} s, one worker "
          f"{med['one_s']:.2f} s, two workers {med['two_s']:.2f} s (wall: two/one {med['speedup']:.2f}x, one/serial "
          f"{med['one_over_serial']:.2f}); busy: one worker {100 * med['busy_one']:.1f} %, two {100 * med['busy_two']:.1f} % "
          f"(scaling {scaling:.2f}); CPU obtained two/one {med['cpu_ratio']:.2f} (efficiency {med['efficiency']:.2f}); "
          f"scheduler overhead {100 * med['overhead']:.1f} % of {med['work_cpu_s']:.2f} CPU-s of work; started: "
          + ", ".join(f"{k} {v:.1f}" for k, v in started.items()))  # fmt: skip
    assert scaling >= SCALING_MIN
    assert med["efficiency"] >= EFFICIENCY_MIN
    assert med["overhead"] < OVERHEAD_MAX

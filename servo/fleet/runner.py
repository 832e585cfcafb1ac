"""Run a fleet's tasks on Dask (``dask.distributed``), or in this process.

Where the tasks run (:class:`Where`):

* ``scheduler="tcp://HOST:PORT"``: an existing cluster (``dask scheduler`` and
  ``dask worker`` processes that can import ``servo`` and read the recordings' paths);
* otherwise, for more than :data:`IN_PROCESS_MAX` tasks, a local cluster of
  ``workers`` processes (default: one per CPU), one thread each, started for the command
  and stopped after it;
* ``workers=0``, or a handful of tasks: this process, one after the other (no cluster
  to start).

Tasks go to the workers in batches (:func:`batches`: several drives per Dask task when
each is tiny, but at least :data:`BATCHES_PER_WORKER` batches per worker so the load
balances).  A task carries a recording's *path*, never its data: the workers read the
recordings.  Each worker process imports the kernels once, from Numba's on-disk cache,
and reuses them for every task.  A worker that dies mid-run loses nothing: the
scheduler reruns its tasks elsewhere; a batch that keeps killing workers
(``distributed``'s ``allowed-failures``) gets an error in each of its rows.  The rows
come back in the tasks' order whatever the order of completion, so the table of a
cluster run equals the table of a serial run row for row.

:func:`map_batches` is that path for any function of a batch of items: the fleet's
commands (:func:`run`, rows of :mod:`servo.fleet.task`) and the detection study of
:mod:`studies.concealed` run through it.
"""
from __future__ import annotations

import logging
import os
import time
import warnings
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Callable

from servo.errors import ConfigError
from servo.io import progress
from servo.fleet.task import ADAPTERS, Task, error_line, failed_row, run_batch

#: at most this many tasks run in this process when no cluster is named
IN_PROCESS_MAX = 4
BATCHES_PER_WORKER = 4
CONNECT_TIMEOUT_S = 10
#: the log file of the :func:`dask_logs` block running, where a local cluster's workers write
_LOG: ContextVar[str | None] = ContextVar("servo_fleet_log", default=None)


@dataclass(frozen=True)
class Where:
    """Where to run: ``scheduler`` address of an existing cluster, or a local cluster
    of ``workers`` processes (None: one per CPU; 0: this process); ``batch``: drives per
    Dask task (None: the command's default)."""

    scheduler: str | None = None
    workers: int | None = None
    batch: int | None = None

    def check(self) -> None:
        if self.workers is not None and self.workers < 0:
            raise ConfigError(f"fleet: --workers {self.workers}: expected 0 (this process) or more")
        if self.batch is not None and self.batch < 1:
            raise ConfigError(f"fleet: --batch {self.batch}: expected at least 1")
        if self.scheduler is not None and self.workers is not None:
            raise ConfigError("fleet: --workers sizes a local cluster; with --scheduler the cluster has its own")


def local_workers(where: Where) -> int:
    """Size of the local cluster: ``where.workers`` or the CPUs this process may use."""
    if where.workers is not None:
        return where.workers
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:
        return os.cpu_count() or 1


def batches(tasks: list, size: int, workers: int) -> list[list]:
    """Consecutive groups of at most ``size`` tasks, smaller if that would leave fewer
    than :data:`BATCHES_PER_WORKER` batches per worker."""
    if not tasks:
        return []
    size = max(1, min(size, len(tasks) // (BATCHES_PER_WORKER * max(workers, 1))))
    return [tasks[i : i + size] for i in range(0, len(tasks), size)]


class Progress:
    """A fleet's progress on a reporter (:class:`servo.io.progress.Reporter`: stderr,
    rate-limited, nothing with ``--quiet``): items done/total (``unit``: drives), how
    many failed (a row or result with an ``error``), time left.  Called with each
    batch's rows.

    The time left is the remaining items at the rate since every worker's first batch
    came back (:meth:`servo.io.progress.Reporter.rebase` at the ``workers``-th batch):
    the workers start their first batches together, so those come back together, and a
    rate counted from the first of them credits the others' work to the time after it
    (on 8 drives and 2 workers, a time left a third short at half-way)."""

    def __init__(self, reporter, total: int, unit: str = "drives"):
        self.reporter, self.unit, self.failed, self.workers = reporter, unit, 0, 1
        self.start(total)

    def start(self, total: int) -> None:
        """(Re)start the count: ``total`` items to run (fewer after ``--resume``)."""
        self.total, self.batches = total, 0
        self.reporter.stage("", total, self.unit)

    def __call__(self, rows: list) -> None:
        self.failed += sum(bool(r.get("error")) for r in rows)
        self.reporter.advance(len(rows), f"{self.failed} failed")
        self.batches += 1
        if self.batches == self.workers:
            self.reporter.rebase()

    def connected(self, client) -> None:
        """Say where to watch the cluster (its dashboard's address, when it has one),
        and count its workers (for the time left)."""
        link = dashboard_link(client)
        try:
            self.workers = max(len(client.scheduler_info().get("workers", {})), 1)
        except Exception:  # noqa: BLE001  (a cluster that cannot say: one worker)
            self.workers = 1
        self.reporter.note(f"Dask dashboard at {link}" if link else "no Dask dashboard (it needs bokeh: "
                           "pip install 'servo-vcm[dashboard]')")  # fmt: skip


def placed(where: Where, n_tasks: int, cluster_min: int) -> Where:
    """``where`` for ``n_tasks`` tasks of a command that pays a local cluster's start
    (~2 s, and each worker's imports, 2-6 s, idle) only from ``cluster_min`` tasks: the
    default place (no ``--workers``, no ``--scheduler``) becomes this process below that;
    a cluster asked for (``--workers N``, ``--scheduler``) is kept."""
    if where.scheduler is None and where.workers is None and n_tasks < cluster_min:
        return Where(workers=0, batch=where.batch)
    return where


def describe(where: Where, n_tasks: int) -> str:
    """Where ``n_tasks`` tasks will run, in words."""
    if where.scheduler is not None:
        return f"the Dask cluster at {where.scheduler}"
    if where.workers == 0 or n_tasks <= IN_PROCESS_MAX:
        return "this process"
    n = min(local_workers(where), n_tasks)
    return f"a local Dask cluster of {n} worker process{'es' if n != 1 else ''}"


def _in_process(fn, items: list, on_results) -> list:
    out = []
    for item in items:
        with progress.reporting(progress.QUIET):  # an item's own stages are not the fleet's progress
            got = fn([item])
        out += got
        on_results(got)
    return out


#: the most a Dask handshake may claim to hold (a real one is a few hundred bytes)
HANDSHAKE_MAX_BYTES = 1 << 16


def _recv(sock, n: int) -> bytes:
    out = b""
    while len(out) < n:
        got = sock.recv(n - len(out))
        if not got:
            break
        out += got
    return out


def probe_scheduler(address: str, timeout_s: float | None = None) -> None:
    """Check that ``address`` (``tcp://HOST:PORT`` or ``HOST:PORT``) speaks Dask's
    protocol before ``distributed`` trusts it: a Dask scheduler sends its handshake as
    soon as a connection opens (an 8-byte length, then frames: their count, their
    lengths, a msgpack map), so read that within ``timeout_s`` (default
    :data:`CONNECT_TIMEOUT_S`) and refuse, in one line,
    an endpoint that sends nothing (an HTTP server, a dashboard's port), closes, or
    sends something else (a text banner: ``distributed`` would take its first 8 bytes
    for a length of exbibytes).  Other protocols (``tls://``, ``ucx://``...) are left
    to ``distributed``."""
    import socket
    import struct

    timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    if scheme != "tcp":
        return
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    where = f"fleet: --scheduler {address}"
    try:
        port_n = int(port.split("/")[0])
    except ValueError:
        raise ConfigError(f"{where}: expected tcp://HOST:PORT") from None
    deadline = time.monotonic() + timeout_s
    try:
        with socket.create_connection((host, port_n), timeout=timeout_s) as sock:
            sock.settimeout(max(deadline - time.monotonic(), 0.01))
            head = _recv(sock, 8)
            if len(head) == 8:
                (n,) = struct.unpack("<Q", head)
                if 16 <= n <= HANDSHAKE_MAX_BYTES:
                    body = _recv(sock, n)
                    (frames,) = struct.unpack_from("<Q", body) if len(body) >= 8 else (0,)
                    if len(body) == n and 1 <= frames <= 16 and 8 * (frames + 1) <= n:
                        return
    except socket.timeout:
        raise ConfigError(f"{where}: not a Dask scheduler (no Dask handshake within {timeout_s:g} s: an HTTP server "
                          "or a dashboard's port?)") from None  # fmt: skip
    except OSError as exc:
        raise ConfigError(f"fleet: cannot reach the Dask scheduler at {address}: {exc.strerror or exc}") from None
    shown = " ".join(head.decode("ascii", "replace").split())[:24] if head else ""
    said = f"it sent {shown!r}" if shown else "it closed the connection"
    raise ConfigError(f"{where}: not a Dask scheduler ({said}, not a Dask handshake)")


def _client(where: Where, n_tasks: int):
    """A connected ``distributed.Client`` and the local cluster it owns (or None)."""
    from distributed import Client

    if where.scheduler is not None:
        probe_scheduler(where.scheduler)
        try:
            return Client(where.scheduler, timeout=CONNECT_TIMEOUT_S), None
        except (OSError, TimeoutError, ValueError) as exc:
            why = " ".join((str(exc) or type(exc).__name__).split())
            raise ConfigError(f"fleet: cannot reach the Dask scheduler at {where.scheduler}: {why}") from None
    cluster = local_cluster(min(local_workers(where), n_tasks), dashboard_address=dashboard_address(),
                            silence_logs=logging.ERROR)  # fmt: skip
    client = Client(cluster)
    if _LOG.get() is not None:  # the workers' output to the log, before any task runs
        from servo.fleet.workerlog import WorkerOutput

        client.register_plugin(WorkerOutput(_LOG.get()))
    return client, cluster


#: what Dask's nannies set in a worker's environment that a fleet's local workers do without:
#: glibc's malloc given any threshold stops adapting its mmap threshold, so each run's
#: log arrays (MBs) came from fresh pages: ~1700 page faults and 7 % more CPU per drive
WORKER_ENVIRON_DROPPED = ("MALLOC_TRIM_THRESHOLD_",)


#: Dask settings of a fleet's local cluster: its own CPU, which the workers' batches share
#: the cores with, from ~0.10 to ~0.02 CPU-seconds per second of wall for two workers
#: (each worker's profiler sampled its threads every 10 ms; the nannies read the workers'
#: memory every 100 ms; each event loop ticked every 20 ms).  The dashboard then shows no
#: task profiles, and a worker's memory is watched every second.
CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.tick.interval": "200ms",
}


def local_cluster(n_workers: int, **options):
    """A ``distributed.LocalCluster`` of ``n_workers`` processes of one thread each, as
    a fleet runs on: the environment Dask's nannies give their workers (one BLAS/OpenMP
    thread each) less :data:`WORKER_ENVIRON_DROPPED`, and :data:`CLUSTER_CONFIG`.
    ``options``: LocalCluster's."""
    import dask
    from distributed import LocalCluster

    env = {k: v for k, v in (dask.config.get("distributed.nanny.pre-spawn-environ") or {}).items()
           if k not in WORKER_ENVIRON_DROPPED}  # fmt: skip
    with dask.config.set({"distributed.nanny.pre-spawn-environ": env, **CLUSTER_CONFIG}):  # read as each part is made
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, **options)


def dashboard_address() -> str | None:
    """Where a local cluster serves Dask's dashboard: a free port (``":0"``: never a
    port another cluster holds) when ``bokeh``, which draws it, is installed; else
    none."""
    import importlib.util

    return ":0" if importlib.util.find_spec("bokeh") is not None else None


def dashboard_link(client) -> str | None:
    """The address of the dashboard of ``client``'s cluster, or None if it has none."""
    try:
        services = client.scheduler_info().get("services", {})
    except Exception:  # noqa: BLE001  (a cluster that cannot say: no link)
        return None
    return client.dashboard_link if "dashboard" in services else None


@contextmanager
def dask_logs(path: str | Path):
    """While the block runs, the records of ``distributed``'s and ``dask``'s loggers
    and the Python warnings raised in this process go to the file ``path`` (made at the
    first record), not to stderr, which carries the command's progress and its error
    line only; so does everything the workers of a local cluster started in the block
    write (:mod:`servo.fleet.workerlog`).  The loggers' handlers and the warning filters
    are restored after; an empty file is removed."""
    token = _LOG.set(str(path))  # a local cluster's workers write there too (servo.fleet.workerlog)
    handler = logging.FileHandler(path, delay=True, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    saved = []
    for name in ("distributed", "dask"):
        lg = logging.getLogger(name)
        saved.append((lg, lg.handlers[:], lg.propagate))
        lg.handlers, lg.propagate = [handler], False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.showwarning = lambda message, category, filename, lineno, file=None, line=None: \
                logging.getLogger("distributed").warning(warnings.formatwarning(message, category, filename, lineno, line).strip())  # fmt: skip
            yield
    finally:
        for lg, handlers, propagate in saved:
            lg.handlers, lg.propagate = handlers, propagate
        handler.close()
        _LOG.reset(token)
        if Path(path).is_file() and Path(path).stat().st_size == 0:  # workers opened it, nothing was written
            Path(path).unlink()


def map_batches(fn: Callable[[list], list], items: list, where: Where = Where(), default_batch: int = 1,
                on_results: Callable[[list], None] | None = None, failed: Callable[[list, str], list] | None = None,
                client=None, on_client: Callable[[object], None] | None = None,
                warm: tuple[str, ...] = ()) -> list:  # fmt: skip
    """``fn(batch)`` (a list of items -> one result per item, in order) over ``items``:
    on a Dask cluster in batches (:func:`batches`) or in this process one item at a time
    (module doc); the results come back in the items' order, whatever the order of
    completion.  ``fn`` must be importable by the workers (a module-level function, or a
    ``functools.partial`` of one).  ``on_results(results)`` is called with each batch's
    results as they complete (progress, checkpoints).  ``failed(batch, why)``: the results
    of a batch that could not run (its workers kept dying; default: raise).  ``client``:
    an already connected ``distributed.Client`` to run on (left open), instead of
    ``where``'s cluster.  ``on_client(client)``: called once connected to a cluster
    (to say where to watch it: :func:`dashboard_link`).  ``warm``: modules the workers of
    a local cluster started here import as they join, before their first batch
    (:mod:`servo.fleet.warm`; a ``--scheduler`` cluster or a ``client`` given is left as it
    is: a plug-in would stay registered on its scheduler)."""
    where.check()
    on_results = on_results or (lambda results: None)
    if not items:
        return []
    if client is None and where.scheduler is None and (where.workers == 0 or len(items) <= IN_PROCESS_MAX):
        return _in_process(fn, items, on_results)
    from distributed import as_completed

    own = client is None
    cluster = None
    if own:
        client, cluster = _client(where, len(items))
    try:
        if on_client is not None:
            on_client(client)
        if cluster is not None and warm:  # after the dashboard's line: the imports take seconds
            from servo.fleet.warm import WarmImports

            client.register_plugin(WarmImports(warm))
        n_workers = max(len(client.scheduler_info().get("workers", {})), 1)
        groups = batches(items, where.batch or default_batch, n_workers)
        futures = {client.submit(fn, g, pure=False): i for i, g in enumerate(groups)}
        results: list = [None] * len(groups)
        for fut in as_completed(futures):
            i = futures[fut]
            try:
                got = fut.result()
            except Exception as exc:  # the batch could not run (its workers kept dying)
                if failed is None:
                    raise
                got = failed(groups[i], f"worker failure: {error_line(exc)}")
            results[i] = got
            on_results(got)
            fut.release()
        return [r for got in results for r in got]
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()


def _rows(command: str, settings: dict, tasks: list[Task]) -> list[dict]:
    return run_batch(command, tasks, settings)


def _failed_rows(settings: dict, tasks: list[Task], why: str) -> list[dict]:
    return [failed_row(t, settings, why) for t in tasks]


def run(command: str, tasks: list[Task], settings: dict, where: Where = Where(), default_batch: int = 1,
        on_rows: Callable[[list], None] | None = None, client=None,
        on_client: Callable[[object], None] | None = None) -> list[dict]:  # fmt: skip
    """Rows of ``tasks`` (:func:`servo.fleet.task.run_batch`), in the tasks' order
    (:func:`map_batches`; a batch whose workers kept dying gets ``worker failure: ...``
    in each of its rows).  ``on_rows(rows)`` is called with each batch's rows as they
    complete (progress, checkpoints)."""
    return map_batches(partial(_rows, command, settings), tasks, where, default_batch, on_rows,
                       partial(_failed_rows, settings), client, on_client, warm_modules(command))  # fmt: skip


def warm_modules(command: str) -> tuple[str, ...]:
    """What a worker of ``command`` imports as it joins: its adapter module and the
    modules the adapter names in ``WARM`` (those it imports inside its functions, to
    keep the client light)."""
    import importlib

    name = ADAPTERS[command]
    return (name, *getattr(importlib.import_module(name), "WARM", ()))


__all__ = ["CLUSTER_CONFIG", "IN_PROCESS_MAX", "Progress", "Where", "batches", "dashboard_address", "dashboard_link", "dask_logs", "describe",
           "local_cluster", "local_workers", "map_batches", "placed",
           "probe_scheduler", "run", "warm_modules"]

"""A fleet's unit of work: one drive, its resume key, and the row it becomes.

Each command registers an adapter module in :data:`ADAPTERS` (one line per command):
``run(payload, settings) -> dict`` turns one recording or drive into the command's
columns by calling the single-drive job as a library (imported inside ``run``: the
client only builds tasks; ``WARM`` lists those modules, which each worker of a local
cluster imports as it joins, :mod:`servo.fleet.warm`).  :func:`run_task` wraps it into a
row with the columns every fleet table has (:data:`LEADING`, :data:`TRAILING`): a
recording or drive that fails gets its one-line error in its row (``status`` "error")
instead of stopping the fleet.  :func:`run_batch` is what a Dask worker runs: a few
tasks in a row, so that tiny tasks do not drown in scheduling.
"""
from __future__ import annotations

import hashlib
import importlib
import json
from dataclasses import dataclass
from typing import Any

from servo._version import __version__
from servo.errors import ConfigError, ServoError

#: command -> module with ``run(payload, settings) -> dict`` (imported by the worker)
ADAPTERS = {
    "identify": "servo.fleet.identify",
    "diagnose": "servo.fleet.diagnose",
    "simulate": "servo.fleet.simulate",
}
#: the most drives a fleet may hold: the client keeps every row in memory, a few kB each
#: (a ``simulate`` row, the widest, ~6 kB with its table), so about 1 GB at the limit
MAX_DRIVES = 100_000
#: first columns of every table, in this order; the command's columns follow, sorted
LEADING = ("drive", "status", "error", "source", "sha256", "key")
#: last columns of every table
TRAILING = ("settings", "servo_version")


@dataclass(frozen=True)
class Task:
    """One drive: its ``drive`` name, resume ``key``, ``source`` (a path, or what was
    simulated), the ``sha256`` of its content, and the adapter's ``payload``."""

    drive: str
    key: str
    source: str
    sha256: str
    payload: Any


def check_size(n: int, what: str = "--drives", more: bool = False) -> None:
    """Refuse, in one line naming the value and the limit, a fleet of ``n`` drives
    (``more``: at least ``n``) beyond :data:`MAX_DRIVES`, before anything is drawn, read
    or allocated."""
    if n > MAX_DRIVES:
        raise ConfigError(f"fleet: {what}: {'over ' * more}{n - more} drives, at most {MAX_DRIVES} per fleet (its rows "
                          "are held in memory, ~1 GB at the limit); split the fleet")  # fmt: skip


def canonical(obj) -> str:
    """Deterministic JSON text of settings (sorted keys, no spaces)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def code_versions() -> dict:
    """The versions of the code that computes a row: this package's and those of the
    libraries whose versions change numbers (:data:`servo.io.provenance.LIBRARIES`)."""
    from servo.io.provenance import LIBRARIES, library_versions, package_version

    return {"servo": package_version(), **library_versions(LIBRARIES)}


def task_key(sha256: str, settings: dict, options: dict | None = None, versions: dict | None = None) -> str:
    """The resume key of one drive (hex, 32 chars): everything that shapes its row,
    hashed together: the content hash of its input, the command's ``settings``, the
    drive's own ``options`` (a recording's column mapping and scales) and the
    ``versions`` of the code (default :func:`code_versions`).  A row is reused only
    under an equal key: a changed input, setting, mapping, scale or version runs again."""
    what = {"content": sha256, "settings": settings, "options": options or {},
            "versions": code_versions() if versions is None else versions}  # fmt: skip
    return hashlib.sha256(canonical(what).encode()).hexdigest()[:32]


def error_line(exc: BaseException) -> str:
    """One line for a failed drive: the message of a :class:`ServoError` (bad data, a
    fit that cannot be trusted, a diverging simulation), else ``internal error: ...``."""
    if isinstance(exc, ServoError):
        text = str(exc)
    else:
        text = f"internal error: {type(exc).__name__}: {exc}"
    return " ".join(text.split())


def _row(task: Task, settings: dict, columns: dict, error: str | None) -> dict:
    return {"drive": task.drive, "status": "ok" if error is None else "error", "error": error, "source": task.source,
            "sha256": task.sha256, "key": task.key, **columns, "settings": canonical(settings),
            "servo_version": __version__}  # fmt: skip


def failed_row(task: Task, settings: dict, error: str) -> dict:
    """The row of a task that could not run at all (its worker kept dying, say)."""
    return _row(task, settings, {}, " ".join(error.split()))


def run_task(command: str, task: Task, settings: dict) -> dict:
    """The row of ``task``: :data:`LEADING`, the adapter's columns, :data:`TRAILING`."""
    try:
        columns = importlib.import_module(ADAPTERS[command]).run(task.payload, settings)
    except Exception as exc:  # the fleet goes on: the error is the row's
        return _row(task, settings, {}, error_line(exc))
    return _row(task, settings, columns, None)


def run_batch(command: str, tasks: list, settings: dict) -> list[dict]:
    """Rows of ``tasks``, in order (what one Dask task runs)."""
    return [run_task(command, t, settings) for t in tasks]


__all__ = ["ADAPTERS", "LEADING", "MAX_DRIVES", "check_size", "TRAILING", "Task", "canonical", "error_line", "failed_row", "run_batch", "run_task", "task_key",
           "code_versions"]

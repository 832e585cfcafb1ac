"""What a local Dask cluster's worker processes write goes to the fleet's log, not the terminal.

A worker of a local cluster is a process of its own that inherits the command's
standard output and error: a Python warning raised in a task, a log record of a library
(numba, numpy's floating-point warnings, a plug-in controller's own), a ``print``, or
what compiled code writes would appear between the command's progress lines.
:class:`WorkerOutput`, registered on the cluster before the first task
(:func:`servo.fleet.runner.map_batches`), points both of each worker's descriptors at
the log file (``dask.log``, :func:`servo.fleet.runner.dask_logs`), so every one of them
lands there (appended: the workers and the command share the file line by line).  Workers of a scheduler given with
``--scheduler`` run elsewhere and keep their own output.
"""
from __future__ import annotations

import os
import sys

from distributed.diagnostics.plugin import WorkerPlugin


class WorkerOutput(WorkerPlugin):
    """Each worker's standard output and error (its warnings, records, prints) appended to ``path``."""

    name = "servo-worker-output"

    def __init__(self, path: str):
        self.path = str(path)

    def setup(self, worker) -> None:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.dup2(fd, 1)
            os.dup2(fd, 2)
        finally:
            os.close(fd)


__all__ = ["WorkerOutput"]

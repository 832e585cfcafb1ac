"""Each Dask worker imports the fleet command's module (and so loads its kernels) once, when it joins.

A fleet's worker runs many batches; what its first batch would otherwise pay before
its first drive (importing ``servo``, numpy, scipy, Numba and the command's kernels
from Numba's on-disk cache: 1-6 s) is paid by :class:`WarmImports` as the worker
joins the cluster, once, and every batch after finds the kernels loaded.  A worker
that joins later (one restarted after a crash) runs it too.  Registered by
:func:`servo.fleet.runner.map_batches` on the local clusters it starts, with the
modules a command's adapter names (``WARM``, :mod:`servo.fleet.task`).
"""
from __future__ import annotations

import importlib
import time

from distributed.diagnostics.plugin import WorkerPlugin


class WarmImports(WorkerPlugin):
    """Import ``modules`` in each worker when it joins (an import that fails is left to
    the first task that needs it, which then reports it in its rows)."""

    name = "servo-warm-imports"

    def __init__(self, modules: tuple[str, ...]):
        self.modules = tuple(modules)
        self.seconds = None

    def setup(self, worker) -> None:
        t0 = time.perf_counter()
        for name in self.modules:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001  (the task that needs it says why, in its rows)
                pass
        self.seconds = time.perf_counter() - t0


__all__ = ["WarmImports"]

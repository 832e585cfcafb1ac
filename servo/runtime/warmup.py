"""Compiling the kernels: saying so while it happens, and doing it ahead (``servo warmup``).

The first command after an install or an edit compiles the Numba kernels (10-20 s on an
idle machine, minutes on a loaded one) before it can start; afterwards they load from
the on-disk cache in about a second (:mod:`kernels._cache`, under the Python
environment's ``var/cache/kernels-numba`` unless ``SERVO_NUMBA_CACHE`` names a folder).

* :func:`announce` prints, while kernels compile, a line on stderr saying what and for
  how long (nothing when they load from the cache quickly);
* :func:`compile_all` compiles every kernel module and every registered controller
  kind's composed kernels: what ``servo warmup`` runs, so that the first real command
  starts at once.
"""
from __future__ import annotations

import importlib
import pkgutil
import sys
import time
from contextlib import contextmanager
from typing import TextIO

from kernels import _cache


#: seconds between two lines while kernels compile
EVERY_S = 5.0


class CompileLines:
    """The :func:`kernels._cache.watch` callback of :func:`announce`: counts the kernels
    compiled and loaded and writes a plain line at most every :data:`EVERY_S` seconds
    once compiling has taken ``progress.DELAY_S`` seconds, and a last one when the
    command ends."""

    def __init__(self, command: str, stream: TextIO):
        from servo.io import progress

        self.progress, self.command, self.stream = progress, command, stream
        self.compiled = self.loaded = 0
        self.seconds = 0.0  # spent compiling
        self.t0 = self.last = None
        self.said = False

    def __call__(self, name: str, compiled: bool | None, seconds: float) -> None:
        now = time.perf_counter()
        if compiled is None:
            if self.t0 is None:
                self.t0 = now
            p = self.progress
            if self.compiled and now - self.t0 >= p.DELAY_S and (self.last is None or now - self.last >= max(p.EVERY_S, EVERY_S)):
                self.line(f"compiling the kernels (once after an install or an edit; `servo warmup` does it ahead): "
                          f"{self.compiled} compiled, {self.loaded} loaded, {self.seconds:.1f} s, now {name}")  # fmt: skip
            return
        if compiled:
            self.compiled += 1
            self.seconds += seconds
        else:
            self.loaded += 1

    def line(self, text: str) -> None:
        self.last, self.said = time.perf_counter(), True
        print(f"{self.command}: {text}", file=self.stream, flush=True)

    def close(self) -> None:
        if self.said:
            self.line(f"compiled {self.compiled} kernels in {self.seconds:.1f} s (cached in {_cache.base_dir()}; "
                      "the next run loads them)")  # fmt: skip


@contextmanager
def announce(command: str = "servo", stream: TextIO | None = None, quiet: bool = False):
    """Within the block, kernels that compile are reported on ``stream`` (stderr) as
    :class:`CompileLines` says; ``quiet``: nothing."""
    if quiet:
        yield None
        return
    lines = CompileLines(command, sys.stderr if stream is None else stream)
    with _cache.watch(lines):
        try:
            yield lines
        finally:
            lines.close()


def compile_all() -> dict:
    """Compile (or load) every kernel of :mod:`kernels` and the composed kernels of every
    registered controller kind; returns ``{"compiled": n, "loaded": n, "seconds": s,
    "cache": folder}``."""
    import kernels

    counts = {"compiled": 0, "loaded": 0}
    t0 = time.perf_counter()

    def count(name, compiled, seconds):
        if compiled is not None:
            counts["compiled" if compiled else "loaded"] += 1

    with _cache.watch(count):
        from servo.controllers import KINDS  # the kinds' own kernels

        for m in pkgutil.iter_modules(kernels.__path__):
            if not m.name.startswith("_"):
                importlib.import_module(f"kernels.{m.name}")
        for kind in KINDS.values():
            kind.kernels()
        _cache.load_helpers()  # those no composed kernel compiled here needed (all, when every caller was cached)
    return {**counts, "seconds": time.perf_counter() - t0, "cache": str(_cache.base_dir())}


__all__ = ["CompileLines", "announce", "compile_all"]

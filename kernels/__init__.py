"""Numba-compiled per-sample kernels.

Pure arithmetic on float64 scalars and preallocated arrays: no Python objects, no I/O, no
allocation in the per-sample path.  Every kernel has an explicit signature, so importing
its module compiles (or loads from the on-disk cache) it before any loop runs; the
kernels composed per controller kind (:mod:`kernels.compose`) are compiled when the kind
is first used, before its loop starts.  A helper only other kernels call (the plant's
sub-step, the Dahl model, the compensator's terms, ...) is loaded only when a kernel
calling it is compiled or Python first calls it (``kernel(..., helper=True)``,
:mod:`kernels._cache`): a cached composed kernel carries its helpers' code.  Importing this package compiles nothing: a
command compiles only the modules it imports (the names below are loaded on first use;
importing every module, ``pkgutil.iter_modules(kernels.__path__)``, compiles them all).
Imports numpy and numba only.  The compiled code is cached on disk in a directory keyed
by the kernels' source (:mod:`kernels._cache`), so editing any kernel recompiles all.
"""
from __future__ import annotations

import importlib

_WHERE = {
    **dict.fromkeys(("FAST", "SLOW", "compensate", "direction", "regime_switch", "velocity_estimate"), "compensator"),
    **dict.fromkeys(("LOG_COLUMNS", "STATS_SIZE", "compose", "error_stats"), "compose"),
    **dict.fromkeys(("dahl_closed", "dahl_flow", "dahl_slope", "dahl_update"), "dahl"),
    "shift_in": "delay",
    **dict.fromkeys(("holding_pi", "holding_pi_bumpless"), "holding"),
    "dahl_trace": "hysteresis",
    **dict.fromkeys(("PLANT_PARAMS", "PLANT_STATE", "plant_measure", "plant_step"), "plant"),
    **dict.fromkeys(("mode_trace", "multistep"), "predict"),
    **dict.fromkeys(("STAGE_PARAMS", "STAGE_STATE", "stage_output", "stage_room", "stage_start", "stage_update"), "stage"),
}


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f"kernels.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'kernels' has no attribute {name!r}")


__all__ = sorted(_WHERE)

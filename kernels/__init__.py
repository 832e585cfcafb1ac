"""Numba-compiled per-sample kernels.

Pure arithmetic on float64 scalars and preallocated arrays: no Python objects, no I/O, no
allocation in the per-sample path.  Every kernel has an explicit signature, so importing
this package compiles (or loads from the on-disk cache) all of them before any loop runs;
the kernels composed per controller kind (:mod:`kernels.compose`) are compiled when the
kind is first used, before its loop starts.  Imports numpy and numba only.  The compiled
code is cached on disk in a directory keyed by the kernels' source (:mod:`kernels._cache`),
so editing any kernel recompiles all.
"""
from kernels.compensator import FAST, SLOW, compensate, direction, regime_switch, velocity_estimate
from kernels.compose import LOG_COLUMNS, STATS_SIZE, compose, error_stats
from kernels.dahl import dahl_closed, dahl_flow, dahl_slope, dahl_update
from kernels.delay import shift_in
from kernels.holding import holding_pi, holding_pi_bumpless
from kernels.hysteresis import dahl_trace
from kernels.plant import PLANT_PARAMS, PLANT_STATE, plant_measure, plant_step
from kernels.predict import mode_trace, multistep
from kernels.stage import STAGE_PARAMS, STAGE_STATE, stage_output, stage_room, stage_start, stage_update

__all__ = [
    "FAST", "LOG_COLUMNS", "PLANT_PARAMS", "PLANT_STATE", "SLOW", "STAGE_PARAMS", "STAGE_STATE", "STATS_SIZE",
    "compensate", "compose", "dahl_closed", "dahl_flow", "dahl_slope", "dahl_trace", "dahl_update", "direction",
    "error_stats", "holding_pi", "holding_pi_bumpless", "mode_trace", "multistep", "plant_measure",
    "plant_step", "regime_switch", "shift_in", "stage_output", "stage_room", "stage_start", "stage_update",
    "velocity_estimate",
]

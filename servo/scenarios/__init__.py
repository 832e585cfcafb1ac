"""Scenario kinds: ``[scenario] kind = "..."`` selects one (``docs/config.md``).

Each kind is one module; registering it is one line here.  A run reads the configured
kind's inputs (:func:`scenario_inputs`) through the runtime's windows
(:mod:`servo.runtime.window`); :mod:`~servo.scenarios.excitation` makes the excitation
signals (multisine, chirp, PRBS) the kinds and the measurements use.
"""
from servo.scenarios.base import (
    KINDS, ArrayInputs, Inputs, ScenarioKind, kind_names, register, scenario_inputs, segments,
)  # fmt: skip
from servo.scenarios.hdd_benchmark import HddBenchmark
from servo.scenarios.steps import Steps

register(Steps)
register(HddBenchmark)

__all__ = ["KINDS", "ArrayInputs", "Inputs", "ScenarioKind", "kind_names", "register", "scenario_inputs", "segments"]

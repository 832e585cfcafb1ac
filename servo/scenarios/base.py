"""Scenario kinds: a run's reference, excitation and disturbance, tick by tick.

``[scenario] kind = "..."`` selects a registered :class:`ScenarioKind`; its
:meth:`~ScenarioKind.inputs` gives the run's :class:`Inputs` and its
:meth:`~ScenarioKind.segments` the named time segments a run's summary reports.  A kind is
one module and one :func:`register` line in :mod:`servo.scenarios`, as a controller kind is.
``cfg`` below is the run's :class:`servo.config.Config` (not imported here: the config sits
above the kinds and takes their names as the choices of ``scenario.kind``).
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np


class Inputs:
    """Per-tick inputs of a run.  Each method takes tick indices (int64, any shape) and
    returns the values (float64, same shape); ticks beyond the signal's end give 0.

    ``reference``: reference position relative to the holding position, m.
    ``excitation``: excitation current added to the controller's output, A.
    ``disturbance``: disturbance force on the arm (simulated drive only), A.
    """

    def reference(self, ticks: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(ticks))

    def excitation(self, ticks: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(ticks))

    def disturbance(self, ticks: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(ticks))

    @classmethod
    def zeros(cls) -> "Inputs":
        """No reference change, no excitation, no disturbance."""
        return cls()


class ArrayInputs(Inputs):
    """Inputs given as arrays, one value per tick from tick 0 (each (n,), any length)."""

    def __init__(self, r=None, u_exc=None, d=None):
        self.r, self.u_exc, self.d = (np.zeros(0) if a is None else np.ascontiguousarray(a, dtype=float)
                                      for a in (r, u_exc, d))  # fmt: skip

    @staticmethod
    def _at(a: np.ndarray, ticks: np.ndarray) -> np.ndarray:
        ticks = np.asarray(ticks)
        inside = ticks < a.shape[0]
        return np.where(inside, a[np.where(inside, ticks, 0)] if a.shape[0] else 0.0, 0.0)

    def reference(self, ticks):
        return self._at(self.r, ticks)

    def excitation(self, ticks):
        return self._at(self.u_exc, ticks)

    def disturbance(self, ticks):
        return self._at(self.d, ticks)


class ScenarioKind:
    """Base of a scenario kind; subclass it, fill ``name`` and ``summary``, define
    :meth:`inputs` and :meth:`segments`, and :func:`register` it."""

    name: ClassVar[str]
    summary: ClassVar[str] = ""

    @classmethod
    def inputs(cls, cfg) -> Inputs:
        """The run's inputs; raise :class:`~servo.errors.ConfigError` for a config the kind
        cannot run."""
        raise NotImplementedError

    @classmethod
    def segments(cls, cfg) -> list[tuple[str, float, float]]:
        """Named time segments ``(name, start s, end s)`` within ``[0, run.duration_s]``."""
        raise NotImplementedError

    @classmethod
    def drive_defaults(cls, scenario) -> dict:
        """``[drive]`` values this kind's scenario (a ``ScenarioConfig``) stands for, used
        where the config leaves the drive at its default (:func:`servo.config.from_dict`);
        ``{}``: the drive's own defaults."""
        return {}


#: The registered kinds, by name, in the order they were registered.
KINDS: dict[str, type[ScenarioKind]] = {}


def register(kind: type[ScenarioKind]) -> type[ScenarioKind]:
    """Make ``kind`` selectable as ``[scenario] kind = "<kind.name>"``.  Checks that it is
    complete: an identifier for a name, not taken, its own inputs and segments."""
    if not (isinstance(kind, type) and issubclass(kind, ScenarioKind)):
        raise TypeError(f"scenario kind {kind!r}: not a ScenarioKind subclass")
    name = getattr(kind, "name", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise TypeError(f"scenario kind {kind.__name__}: name {name!r} must be an identifier")
    for method in ("inputs", "segments"):
        if getattr(kind, method).__func__ is getattr(ScenarioKind, method).__func__:
            raise TypeError(f"scenario kind {kind.__name__}: missing {method}")
    if KINDS.get(name, kind) is not kind:
        raise TypeError(f"scenario kind {kind.__name__}: name {name!r} is taken by {KINDS[name].__module__}."
                        f"{KINDS[name].__name__}")  # fmt: skip
    KINDS[name] = kind
    return kind


def kind_names() -> tuple[str, ...]:
    """The registered kinds' names (``[scenario] kind`` choices).  The built-in kinds are
    registered by the package (:mod:`servo.scenarios`), which Python imports before any of
    its modules."""
    return tuple(KINDS)


def scenario_inputs(cfg) -> Inputs:
    """The inputs of the run's scenario kind, ``cfg.scenario.kind``."""
    return KINDS[cfg.scenario.kind].inputs(cfg)


def segments(cfg) -> list[tuple[str, float, float]]:
    """The named time segments of the run's scenario kind."""
    return KINDS[cfg.scenario.kind].segments(cfg)

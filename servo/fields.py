"""Documented config fields: :func:`P` declares one (default, unit, doc, range or
choices) and :func:`check_value` validates a value against it.

The config sections of :mod:`servo.config` and the controller kinds' own sections
(:mod:`servo.controllers`) are dataclasses of :func:`P` fields; this module sits below
both, so that a controller kind declares its section without importing the config that
gathers the sections.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import field, fields
from typing import Any

from servo.errors import ConfigError


def P(default, unit: str, doc: str, lo=None, hi=None, lo_open=False, hi_open=False, choices=None):
    """A documented config field: default, unit, one-line doc, valid range or choices."""
    meta = dict(unit=unit, doc=doc, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open, choices=choices)
    # choices: a tuple, or a function returning one (the registered controller kinds)
    if isinstance(default, list):
        return field(default_factory=lambda d=tuple(default): list(d), metadata=meta)
    return field(default=default, metadata=meta)


def check_value(key: str, value: Any, f: dataclasses.Field) -> Any:
    m = f.metadata
    kind = f.type if isinstance(f.type, str) else f.type.__name__
    if kind == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"config: {key} must be true or false, got {shown(value)}")
        return value
    if kind == "str":
        if m["choices"] is None:  # free text (a path)
            if not isinstance(value, str):
                raise ConfigError(f"config: {key} must be a string, got {shown(value)}")  # (repr of a 5000-digit int raises)
            return value
        choices = choices_of(m)
        if not isinstance(value, str) or value not in choices:
            raise ConfigError(f"config: {key} must be one of {', '.join(choices)}, got {shown(value)}")
        return value
    if kind == "list":
        if not isinstance(value, list):
            raise ConfigError(f"config: {key} must be a list of numbers, got {shown(value)}")
        if len(value) > MAX_LIST_LENGTH:
            raise ConfigError(f"config: {key} holds {len(value)} values, more than the {MAX_LIST_LENGTH} a list may hold")
        return [check_number(f"{key}[{i}]", v, m, float) for i, v in enumerate(value)]
    return check_number(key, value, m, int if kind == "int" else float)


#: Most values a list field may hold (steps, modes, notches: a run's cost grows with each).
MAX_LIST_LENGTH = 1024


def shown(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters: an error line quotes what was given,
    not a megabyte of it."""
    try:
        text = repr(value)
    except ValueError:  # an integer of more digits than Python converts to text
        return "an integer of thousands of digits"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def choices_of(m: dict) -> tuple:
    c = m["choices"]
    return tuple(c() if callable(c) else c)


def documented(cls) -> list[dataclasses.Field]:
    """The :func:`P` fields of a section dataclass (not the controller's ``kinds``)."""
    return [f for f in fields(cls) if "unit" in f.metadata]


def check_number(key: str, value: Any, m: dict, kind: type) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"config: {key} must be a number, got {shown(value)}")
    if kind is int and not isinstance(value, int):
        raise ConfigError(f"config: {key} must be an integer, got {shown(value)}")
    if isinstance(value, float) and not math.isfinite(value):  # (an int is finite; isfinite overflows on 10**400)
        raise ConfigError(f"config: {key} must be finite, got {shown(value)}")
    if abs(value) > MAGNITUDE_MAX and (m["lo"] is None or m["hi"] is None):
        raise ConfigError(f"config: {key} = {shown(value)} is beyond any physical value ({range_text(m)}, {m['unit']})")
    if value != 0 and abs(value) < SCALE_MIN and m["lo"] == 0 and m["hi"] is None:  # a scale: 5e-324 Hz
        raise ConfigError(f"config: {key} = {shown(value)} is below any value a scale can compute with (0 or at least "
                          f"{SCALE_MIN:g}, {m['unit']})")  # fmt: skip  (a track design divided by it: exit 70)
    lo, hi = m["lo"], m["hi"]
    if lo is not None and (value < lo or (m["lo_open"] and value == lo)):
        raise ConfigError(f"config: {key} = {shown(value)} is out of range ({range_text(m)}, {m['unit']})")
    if hi is not None and (value > hi or (m["hi_open"] and value == hi)):
        raise ConfigError(f"config: {key} = {shown(value)} is out of range ({range_text(m)}, {m['unit']})")
    return kind(value)


MAGNITUDE_MAX = 1e12
"""Bound on the magnitude of a number field whose range has no explicit bound on that
side, and of every recorded value (:mod:`servo.io.recording`; its inverse bounds the
largest value of a recorded column that is not all zero): no servo quantity in SI
units comes near it, and values near 1e300 overflow the plant's matrix exponentials and
the fits (warnings, NaN results)."""

SCALE_MIN = 1e-150
"""Least non-zero value of a field that is a scale (lower bound 0, no upper bound: an
inertia, a frequency, a gain): below it its square underflows and the designs that
divide by it fail (``controller.track.inertia = 5e-324`` was an IndexError, exit 70).
Not 1/MAGNITUDE_MAX: the compensator writes 1e-12 (and less, converted by a force
constant) for a Dahl element that is off."""


def range_text(m: dict, number: bool = True) -> str:
    """The valid range of a field, in words (``true / false`` for a flag)."""
    if not number:
        return "true / false"
    lo = f"{'>' if m['lo_open'] else '>='} {m['lo']:g}" if m["lo"] is not None else f">= {-MAGNITUDE_MAX:g}"
    hi = f"{'<' if m['hi_open'] else '<='} {m['hi']:g}" if m["hi"] is not None else f"<= {MAGNITUDE_MAX:g}"
    return f"{lo} and {hi}"

"""Distributions over ``[drive]`` fields for a Monte Carlo fleet: parse, check, draw.

A spec is a string, one per field::

    drive.Fc = "normal(1e-3, 10%)"      # mean 1e-3, standard deviation 10 % of it
    drive.B  = "normal(2e-3, 1e-4)"     # standard deviation as a number (same unit)
    drive.J  = "uniform(0.9e-3, 1.1e-3)"  # between two bounds
    drive.K  = "uniform(0.1, 20%)"      # centre +- 20 %
    drive.Ha = "lognormal(1e-3, 15%)"   # median 1e-3, ln(value) has standard deviation 0.15

A spec is checked against the field's declaration in :mod:`servo.config` (a float field
of ``[drive]``; its centre, and a uniform's bounds, inside the field's range); every
error is one line naming the field.  Draws outside the field's range (a normal's tails
below a lower bound of 0) are drawn again: the distribution is truncated to the range.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields

import numpy as np

from servo.config import DriveConfig
from servo.errors import ConfigError

KINDS = ("normal", "uniform", "lognormal")
_SPEC = re.compile(r"^\s*(\w+)\s*\(\s*([^,()]+?)\s*,\s*([^,()]+?)\s*\)\s*$")
_FIELDS = {f.name: f for f in fields(DriveConfig)}
MAX_REDRAWS = 100


@dataclass(frozen=True)
class Dist:
    """One field's distribution: ``key`` (``drive.Fc``), ``kind``, ``a`` and ``b`` as
    resolved numbers (normal: mean, sd; uniform: low, high; lognormal: median, sigma of
    the logarithm), and the ``text`` it was given as."""

    key: str
    kind: str
    a: float
    b: float
    text: str

    @property
    def field(self) -> str:
        return self.key.split(".", 1)[1]

    def centre(self) -> float:
        return 0.5 * (self.a + self.b) if self.kind == "uniform" else self.a

    def _raw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.kind == "normal":
            return rng.normal(self.a, self.b, n)
        if self.kind == "uniform":
            return rng.uniform(self.a, self.b, n)
        return self.a * np.exp(rng.normal(0.0, self.b, n))

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` values, redrawn where outside the field's range (shape (n,))."""
        x = self._raw(rng, n)
        for _ in range(MAX_REDRAWS):
            bad = ~in_range(self.field, x)
            if not bad.any():
                return x
            x[bad] = self._raw(rng, int(bad.sum()))
        raise ConfigError(f"fleet: {self.key} = {self.text!r}: most draws fall outside the field's range "
                          f"({_range(self.field)}); narrow the distribution")  # fmt: skip


def _range(name: str) -> str:
    m = _FIELDS[name].metadata
    lo = "-inf" if m["lo"] is None else f"{m['lo']:g}"
    hi = "inf" if m["hi"] is None else f"{m['hi']:g}"
    return f"{'(' if m['lo_open'] else '['}{lo}, {hi}{')' if m['hi_open'] else ']'}"


def in_range(name: str, x: np.ndarray) -> np.ndarray:
    """Which values of ``x`` lie in the declared range of ``drive.<name>`` (bool array)."""
    m = _FIELDS[name].metadata
    ok = np.isfinite(x)
    if m["lo"] is not None:
        ok &= (x > m["lo"]) if m["lo_open"] else (x >= m["lo"])
    if m["hi"] is not None:
        ok &= (x < m["hi"]) if m["hi_open"] else (x <= m["hi"])
    return ok


def _number(key: str, text: str, s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise ConfigError(f"fleet: {key} = {text!r}: {s!r} is not a number") from None
    if not math.isfinite(v):
        raise ConfigError(f"fleet: {key} = {text!r}: {s!r} is not finite")
    return v


def parse_spec(key: str, text) -> Dist:
    """Parse and check ``key = text`` (see module doc); raises a one-line
    :class:`~servo.errors.ConfigError`."""
    section, dot, name = str(key).partition(".")
    if section != "drive" or not dot:
        raise ConfigError(f"fleet: {key}: only [drive] fields can be drawn (drive.NAME)")
    if name not in _FIELDS:
        raise ConfigError(f"fleet: {key}: unknown field of [drive]")
    if _FIELDS[name].type != "float":
        raise ConfigError(f"fleet: {key}: only number fields can be drawn ({key} is a {_FIELDS[name].type})")
    if not isinstance(text, str):
        raise ConfigError(f"fleet: {key} = {text!r}: expected a string such as \"normal(1e-3, 10%)\"")
    m = _SPEC.match(text)
    if not m or m.group(1) not in KINDS:
        raise ConfigError(f"fleet: {key} = {text!r}: expected {', '.join(k + '(A, B)' for k in KINDS)}")
    kind, sa, sb = m.groups()
    a = _number(key, text, sa)
    pct = sb.endswith("%")
    b = _number(key, text, sb[:-1] if pct else sb)
    if kind == "normal":
        b = abs(a) * b / 100 if pct else b
        if not b >= 0:
            raise ConfigError(f"fleet: {key} = {text!r}: the standard deviation must be >= 0")
    elif kind == "uniform":
        if pct:
            a, b = a - abs(a) * b / 100, a + abs(a) * b / 100
        if not b >= a:
            raise ConfigError(f"fleet: {key} = {text!r}: the upper bound must be >= the lower")
    else:
        b = b / 100 if pct else b
        if not a > 0:
            raise ConfigError(f"fleet: {key} = {text!r}: a lognormal's median must be > 0")
        if not b >= 0:
            raise ConfigError(f"fleet: {key} = {text!r}: the spread of the logarithm must be >= 0")
    d = Dist(key, kind, a, b, text)
    points = (a, b) if kind == "uniform" else (a,)
    for p in points:  # the field's declared range (servo.config's P)
        if not in_range(name, np.array([p]))[0]:
            what = "bound" if kind == "uniform" else ("median" if kind == "lognormal" else "mean")
            unit = _FIELDS[name].metadata["unit"]
            raise ConfigError(f"fleet: {key} = {text!r}: the {what} {p:g} is outside the field's range "
                              f"{_range(name)} ({unit})")  # fmt: skip
    return d


def parse_specs(items: dict) -> list[Dist]:
    """``{"drive.Fc": "normal(1e-3, 10%)", ...}`` -> checked distributions (in the given order)."""
    return [parse_spec(k, v) for k, v in items.items()]


def draw_drive(dists: list[Dist], seed: int, i: int) -> dict:
    """Drive ``i`` of a fleet: ``{field: value}`` of every distribution, drawn from a
    generator of its own (``(seed, i)``), so that drive ``i`` is the same whatever the
    fleet's size."""
    rng = np.random.default_rng([seed, i])
    return {d.field: float(d.draw(rng, 1)[0]) for d in dists}


def check_seed(seed: int) -> None:
    """Refuse a seed numpy's generators refuse (a negative one: exit 70 from ``--seed -1``)."""
    if not (isinstance(seed, int) and seed >= 0):
        raise ConfigError(f"--seed {seed!r}: expected a non-negative integer")


def draw_drives(dists: list[Dist], n: int, seed: int) -> list[dict]:
    """Drives ``0..n-1`` (:func:`draw_drive`)."""
    check_seed(seed)
    return [draw_drive(dists, seed, i) for i in range(n)]


__all__ = ["Dist", "KINDS", "check_seed", "draw_drive", "draw_drives", "in_range", "parse_spec", "parse_specs"]

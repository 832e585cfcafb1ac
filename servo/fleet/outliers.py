"""Robust outliers of a fleet: per column, each drive's distance from the median in MADs.

For a column with values ``x`` over the drives that succeeded, the robust score of a
drive is its distance from the median in units of ``1.4826 * MAD`` (the factor makes
it the standard deviation of a normal population), **each side of the median with its
own MAD** (``MAD_low`` over the values below the median, ``MAD_high`` over those above:
the "double MAD"): the figures of real fleets (an RMS error, a friction level) are
rarely symmetric, and one MAD for both sides flags the tail of a skewed population's
long side and hides a low outlier on its short side.  (Scoring the logarithm of a
positive column was tried and dropped: on a normal spread of 20 % it stretches the low
tail and flagged a defect-free drive at 0.45 times the median offset.)

Unlike the mean and the standard deviation, the median and the MADs are not moved by
the outliers themselves (up to half the drives).  A drive is an outlier in a column
when ``|z| > THRESHOLD``.  **Only continuous figures are scored**: a column is not
scored when fewer than :data:`CONTINUOUS_SHARE` of its values are distinct (a figure
quantised by the sensor or the sample period, such as a step's overshoot or settling
time, or one pinned at a limit), when a MAD is zero, or with fewer than
:data:`MIN_DRIVES` values.

The default threshold (5.5) is set by measurement, not by a normal tail: on fleets with
no defect (Monte Carlo fleets with 20 % spreads, identified and diagnosed synthetic
fleets without defects, and populations of 1000 drives drawn from normal, lognormal and
gamma distributions; ``docs/fleet.md``, "Outliers that mean something") at most 1 drive
in 100 is flagged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

THRESHOLD = 5.5
MAD_TO_SD = 1.4826
MIN_DRIVES = 5
#: a column is scored only if at least this share of its values are distinct
CONTINUOUS_SHARE = 0.9


@dataclass(frozen=True)
class Outlier:
    """One drive's outlying value in one column, with the population's median, the MAD
    of both sides and the robust score ``z``."""

    drive: str
    column: str
    value: float
    median: float
    mad: float
    z: float


def _value(v) -> float:
    if v is None or isinstance(v, bool) or not isinstance(v, (int, float)):
        return math.nan
    return float(v)


def continuous(x: np.ndarray) -> bool:
    """Whether the finite values of ``x`` look continuous (module doc): at least
    :data:`MIN_DRIVES` of them, at least :data:`CONTINUOUS_SHARE` distinct."""
    x = x[np.isfinite(x)]
    return x.size >= MIN_DRIVES and np.unique(x).size >= CONTINUOUS_SHARE * x.size


def robust_z(x: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Scores of ``x`` (NaN where ``x`` is, or everywhere when the column is not
    scored), its median, and its MAD (both sides pooled) -- see module doc."""
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    if not continuous(x):
        med = float(np.median(x[ok])) if ok.any() else math.nan
        return np.full(x.shape, np.nan), med, math.nan
    med = float(np.median(x[ok]))
    d = np.where(ok, x - med, 0.0)
    lo = float(np.median(-d[ok & (d <= 0)]))
    hi = float(np.median(d[ok & (d >= 0)]))
    mad = float(np.median(np.abs(d[ok])))
    if not (lo > 0 and hi > 0):
        return np.full(x.shape, np.nan), med, mad
    z = np.where(d >= 0, d / (MAD_TO_SD * hi), d / (MAD_TO_SD * lo))
    return np.where(ok, z, np.nan), med, mad


def outliers(rows: list[dict], columns: list[str], threshold: float = THRESHOLD) -> list[Outlier]:
    """Outliers of ``columns`` among the rows whose ``status`` is ok, largest ``|z|``
    first (ties by drive, then column)."""
    good = [r for r in rows if r.get("status") == "ok"]
    out = []
    for c in columns:
        x = np.array([_value(r.get(c)) for r in good])
        z, med, mad = robust_z(x)
        for i in np.flatnonzero(np.abs(np.nan_to_num(z)) > threshold):
            out.append(Outlier(good[i]["drive"], c, float(x[i]), med, mad, float(z[i])))
    return sorted(out, key=lambda o: (-abs(o.z), o.drive, o.column))


def unscored(rows: list[dict], columns: list[str]) -> list[str]:
    """The ``columns`` that are not scored (quantised, constant on one side, or too few
    values; module doc)."""
    good = [r for r in rows if r.get("status") == "ok"]
    out = []
    for c in columns:
        x = np.array([_value(r.get(c)) for r in good])
        if np.isnan(robust_z(x)[0]).all():
            out.append(c)
    return out


__all__ = ["CONTINUOUS_SHARE", "MAD_TO_SD", "MIN_DRIVES", "Outlier", "THRESHOLD", "continuous", "outliers", "robust_z",
           "unscored"]

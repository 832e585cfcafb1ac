"""Robust outliers of a fleet: per column, each drive's distance from the median in MADs.

For a column with values ``x`` over the drives that succeeded, the robust score of a
drive is ``z = (x - median) / (1.4826 * MAD)``, ``MAD = median(|x - median|)`` (the
factor makes ``1.4826 * MAD`` the standard deviation of a normal population).  Unlike
the mean and the standard deviation, the median and the MAD are not moved by the
outliers themselves (up to half the drives).  A drive is an outlier in a column when
``|z| > THRESHOLD`` (3.5, Iglewicz and Hoaglin's recommendation for the equivalent
modified z-score).  A column whose MAD is zero (half the drives or more share one
value), or with fewer than :data:`MIN_DRIVES` values, is not scored.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

THRESHOLD = 3.5
MAD_TO_SD = 1.4826
MIN_DRIVES = 5


@dataclass(frozen=True)
class Outlier:
    """One drive's outlying value in one column, with the population's median, MAD and
    the robust score ``z``."""

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


def robust_z(x: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Scores of ``x`` (NaN where ``x`` is, or everywhere when unscorable), median, MAD."""
    ok = np.isfinite(x)
    if ok.sum() < MIN_DRIVES:
        return np.full(x.shape, np.nan), math.nan, math.nan
    med = float(np.median(x[ok]))
    mad = float(np.median(np.abs(x[ok] - med)))
    if not mad > 0:
        return np.full(x.shape, np.nan), med, mad
    return (x - med) / (MAD_TO_SD * mad), med, mad


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


__all__ = ["MAD_TO_SD", "MIN_DRIVES", "Outlier", "THRESHOLD", "outliers", "robust_z"]

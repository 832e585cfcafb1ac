"""Quantisation of the position sensor: a sensor effect, found and proved apart.

A quantised sensor leaves the force balance alone (the arm does not feel its encoder),
so it is not a regressor column.  Its evidence is in the positions themselves, and its
cost is noise: a step ``q`` adds ``q^2/12`` of position noise, which the acceleration
path differentiates twice.  Where that noise dominates, the least-squares estimates
are biased (errors in variables: the inertia comes out low) and, in closed loop, the
noise that the controller feeds back into the input makes the residual correlated
with the input, which input-dependent terms then fit.

* **Lattice test** (:func:`lattice_test`).  ``step`` is estimated from the position
  increments (the smallest non-zero one, refined as the median of
  ``|dx|/round(|dx|/step0)``); the offset is the circular mean of the positions'
  fractional parts.  The statistic is the fraction of samples within 1 % of a step from
  the lattice.  Off a lattice that fraction is 2 % (the fractional parts are uniform);
  the test rejects when it is at least one half *and* the binomial tail
  ``P(X >= k; n, 0.02)`` is below ``alpha``.  On continuous data it never fires.
* **Model: a quantisation-aware derivative path** (:func:`candidate_paths`).  The
  quantisation noise is white with variance ``q^2/12``; a narrower band keeps it out of
  the rows.  The paths tried decimate by 2, 4 and 8 times the default factor, the
  Butterworth cutoff scaled alike.
* **Proof.**  The paths' rows differ, so their force errors cannot be compared; the
  simulated output can (the measured positions at full rate).  The baseline is fitted
  on each path's training rows and its short-horizon output error computed on the
  training part, per block of starts.  The best path pays when its per-block log
  ratio to the default path is positive in a one-sided t-test at ``alpha/3`` (three
  paths tried; nothing is fitted per block, so no fold correction) *and* it lowers the
  output NRMSE of the held-out part.  The rest of the diagnosis then runs on it.
  When the step is far below what the model can predict, the default path wins and no
  finding is made, whatever the lattice test says.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

#: a sample is on the lattice within this fraction of a step
TOLERANCE = 0.01
#: fraction of samples on the lattice needed (besides significance)
MIN_FRACTION = 0.5
#: decimation factors tried, as multiples of the default
PATH_FACTORS = (2, 4, 8)


@dataclass
class Lattice:
    """``step``, ``offset`` (m); ``fraction`` of samples on it; ``p`` the binomial
    tail probability of that fraction off a lattice."""

    step: float
    offset: float
    fraction: float
    p: float

    def found(self, alpha: float) -> bool:
        return self.step > 0 and self.fraction >= MIN_FRACTION and self.p < alpha


def lattice_test(x: np.ndarray) -> Lattice:
    """Test whether the positions ``x`` (n,) sit on a lattice (see module doc)."""
    x = np.asarray(x, dtype=float)
    dx = np.abs(np.diff(x))
    scale = max(float(np.max(np.abs(x))), 1e-300)
    nz = dx[dx > 1e-12 * scale]
    if nz.size < 10:
        return Lattice(0.0, 0.0, 0.0, 1.0)
    q0 = float(nz.min())
    k = np.round(nz / q0)
    k = k[(k >= 1) & (k <= 1000)]
    if k.size == 0:
        return Lattice(0.0, 0.0, 0.0, 1.0)
    ok = (nz >= 0.5 * q0) & (nz <= 1000.5 * q0)
    q = float(np.median(nz[ok] / np.round(nz[ok] / q0)))
    if not q > 0:
        return Lattice(0.0, 0.0, 0.0, 1.0)
    ph = 2 * np.pi * (x / q - np.floor(x / q))
    frac_mean = float(np.angle(np.mean(np.exp(1j * ph))) / (2 * np.pi))
    off = (frac_mean % 1.0) * q
    dev = (x - off) / q
    dev = np.abs(dev - np.round(dev))
    on = int(np.count_nonzero(dev <= TOLERANCE))
    n = x.size
    p = float(stats.binom.sf(on - 1, n, 2 * TOLERANCE))
    return Lattice(q, off, on / n, p)


def candidate_paths(settings, fs: float) -> list:
    """Narrower-band settings of the robust path: decimation and Butterworth cutoff
    scaled by each of :data:`PATH_FACTORS`."""
    from dataclasses import replace

    out = []
    for f in PATH_FACTORS:
        out.append(replace(settings, decimate=settings.decimate * f, cutoff_hz=settings.cutoff(fs) / f))
    return out


def improvement_test(e0: np.ndarray, e1: np.ndarray) -> tuple[float, float]:
    """One-sided t-test that the per-block output SSE drops from ``e0`` to ``e1``
    (both (K,)): ``t``, ``p`` of the mean log ratio."""
    d = np.log(np.maximum(e0, 1e-300) / np.maximum(e1, 1e-300))
    sd = d.std(ddof=1)
    if not np.isfinite(sd) or sd == 0:
        return (np.inf, 0.0) if d.mean() > 0 else (0.0, 1.0)
    t = d.mean() / (sd / np.sqrt(d.size))
    return float(t), float(stats.t.sf(t, d.size - 1))


__all__ = ["Lattice", "candidate_paths", "improvement_test", "lattice_test"]

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
  When the step is far below what the model can predict, the default path wins.
* **Named where its noise is the error** (:func:`heldout_on_lattice`,
  :func:`error_share`).  Where the quantum is a few times the sensor's other noise,
  the baseline on the default rows is already at its floor: the floor is estimated
  from the data and holds the quantum's ``q^2/12``, so nothing predicts better on a
  narrower band, yet the quantum makes half the held-out error (the same recording
  without it: 38-46 % lower held-out RMS at a quantum of 5 noise std, 94-98 % at 100).
  The rows then stay as they are and the quantum is named on two held-out facts: the
  test part's positions lie on the training part's lattice (binomial tail at the
  level), and the quantum's white noise, ``q/sqrt(12)`` through the acceleration path
  and the fitted inertia, makes at least :data:`SHARE_MIN` of the baseline's RMS
  residual on the test rows (``1 - sqrt(1 - (floor_q/rms)^2)``: the share of that RMS
  a sensor without the quantum would remove).  A quantum far below what the model
  leaves (EMPS: 50 nm steps against a residual 75 x the encoder's floor) has no share
  to speak of and is not named.
* **The inertia the quantum attenuates** (:func:`acceleration_share`).  The quantum's
  noise is in the acceleration rows, the inertia's regressor, so least squares fits a
  lower inertia (errors in variables: ``J_fit ~ J*(1 - s)``, ``s`` the share of the
  acceleration rows' variance that is the quantum's noise).  Its floor through ``J_fit``
  then reads the quantum's noise ``1 - s`` times too small: a 100-noise-std quantum on an
  open-loop chirp (``s`` 0.78 on the training rows, ``J_fit`` a tenth of the truth) made
  "14 %" of a held-out error it made 90 % of.  The floor uses ``J_fit/(1 - s)``
  (:func:`attenuated_inertia`), and where ``s`` is at least :data:`ACCELERATION_SHARE_MAX`
  the rows cannot resolve the inertia at all: an inertia not positive beyond its
  uncertainty is then the quantum's doing, and the report says so
  (:func:`scope_reason`), not that the input does not drive a mass.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from servo.diagnose.verdict import acceleration_noise_gain

#: a sample is on the lattice within this fraction of a step
TOLERANCE = 0.01
#: fraction of samples on the lattice needed (besides significance)
MIN_FRACTION = 0.5
#: decimation factors tried, as multiples of the default
PATH_FACTORS = (2, 4, 8)
#: a quantum is named on the default rows when its noise makes at least this share of
#: the baseline's held-out RMS residual (the issue's "changes the held-out error by 20 %")
SHARE_MIN = 0.2
#: the quantum's share of the acceleration rows' variance at which the rows cannot resolve
#: the inertia (its attenuation ``1 - s`` at most a half); also the largest ``s`` the
#: correction :func:`attenuated_inertia` divides by
ACCELERATION_SHARE_MAX = 0.5


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


def heldout_on_lattice(x: np.ndarray, lat: Lattice) -> tuple[float, float]:
    """Whether the positions ``x`` (n,) (the held-out part's) lie on the lattice ``lat``
    found on other samples: the fraction within :data:`TOLERANCE` of a step, and the
    binomial tail ``P(X >= k; n, 2*TOLERANCE)`` of that count off a lattice."""
    x = np.asarray(x, dtype=float)
    if lat.step <= 0 or x.size == 0:
        return 0.0, 1.0
    dev = (x - lat.offset) / lat.step
    on = int(np.count_nonzero(np.abs(dev - np.round(dev)) <= TOLERANCE))
    return on / x.size, float(stats.binom.sf(on - 1, x.size, 2 * TOLERANCE))


def quantum_floor(step: float, J: float, settings, fs: float) -> float:
    """Force-residual std per row (force unit) that a quantum ``step`` (m) makes as white
    noise of variance ``step^2/12`` through the acceleration path of ``settings`` at
    ``fs`` (Hz) and the inertia ``J``: the noise floor of :mod:`servo.diagnose.verdict`
    with the quantum's noise in place of the sensor's."""
    return abs(J) * step / np.sqrt(12.0) * acceleration_noise_gain(settings, fs)


def acceleration_share(step: float, accel_rows: np.ndarray, settings, fs: float) -> float:
    """The share ``s`` of the variance of the acceleration rows ``accel_rows`` (m,)
    (m/s^2, the rows the inertia was fitted on) that a quantum ``step`` (m) makes: its
    white noise ``step/sqrt(12)`` through the acceleration path of ``settings`` at
    ``fs`` (Hz), squared, over the rows' variance (at most 1)."""
    a = np.asarray(accel_rows, dtype=float)
    if a.size < 2:
        return 0.0
    var = float(np.var(a))
    noise = (step / np.sqrt(12.0) * acceleration_noise_gain(settings, fs)) ** 2
    return float(min(noise / var, 1.0)) if var > 0 else 1.0


def attenuated_inertia(J: float, share: float) -> float:
    """The inertia ``J`` (F s^2/m) fitted on acceleration rows of which ``share`` is the
    quantum's noise, corrected for the attenuation that noise causes (errors in
    variables, module doc): ``J/(1 - share)``, ``share`` capped at
    :data:`ACCELERATION_SHARE_MAX`."""
    return J / (1.0 - min(max(share, 0.0), ACCELERATION_SHARE_MAX))


def scope_reason(step: float, share: float, J: float | None, J_std: float | None) -> str:
    """The out-of-scope reason of a recording whose inertia is not positive beyond its
    uncertainty where a quantum ``step`` (m) makes ``share`` of the acceleration rows'
    variance: the quantum's, when that share is at least :data:`ACCELERATION_SHARE_MAX`
    ("" otherwise: the inertia's own reason stands)."""
    if share < ACCELERATION_SHARE_MAX:
        return ""
    jt = "none" if J is None else f"{J:.3g} +- {J_std or 0.0:.2g}"
    return (f"the position sensor's quantum ({step:.3g} m) makes {100 * share:.0f} % of the acceleration the rows read, "
            f"so the inertia cannot be resolved (fitted J {jt}, pulled towards zero by that noise); a finer position "
            "sensor or a larger motion would resolve it")  # fmt: skip


def error_share(floor_q: float, rms: float) -> float:
    """The share of a residual's RMS ``rms`` that a noise of RMS ``floor_q`` within it
    makes: ``1 - sqrt(1 - (floor_q/rms)^2)``, what removing that noise removes (1 when
    the noise is all of it or more)."""
    if not rms > 0:
        return 0.0
    r = min(floor_q / rms, 1.0)
    return float(1.0 - np.sqrt(1.0 - r * r))


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


__all__ = ["ACCELERATION_SHARE_MAX", "SHARE_MIN", "Lattice", "acceleration_share", "attenuated_inertia",
           "candidate_paths", "error_share", "heldout_on_lattice", "improvement_test", "lattice_test", "quantum_floor",
           "scope_reason"]

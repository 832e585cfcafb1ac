"""The one stepped-sine demodulator: the complex amplitude of a sine of known frequency
in sampled signals, over a window of whole periods, with its uncertainty.

Per signal ``y`` (a column of ``Y``), over the window's times ``t`` (s, counted from the
excitation's phase zero), the least-squares fit::

    y(t) = c0 + c1*(t - mean(t)) + a*cos(w*t) + b*sin(w*t)        w = 2*pi*f

gives the complex amplitude ``Y(f) = a - j*b``.  Over whole periods in whole samples
the sine's columns are orthogonal to the offset, so without the drift column this is
the single-bin DFT ``2/n * sum y[k]*exp(-j*w*t_k)`` of the mean-removed signal (no
leakage); the drift column ``c1`` keeps a slow transient still decaying in the window
from leaking into the amplitude (the three-parameter sine fit at a known frequency of
IEEE Std 1057, with a linear trend added).

Uncertainty, two ways, both returned:

* ``std``: the least-squares standard error of each complex component (``a`` and
  ``-b``), ``sqrt(s2 * diag((A^T A)^-1))`` with ``s2 = RSS/(n - 4)`` the residual
  variance, averaged over the two components.  Right for noise that is white over the
  window (about ``sigma*sqrt(2/n)``); it says nothing of a disturbance at ``f`` itself.
* ``per_period``: the same fit over each period alone; the spread of a ratio of two
  signals' per-period amplitudes, ``std(H_i)/sqrt(periods)``, is the estimate's
  standard deviation also where the two signals' noises are correlated (a loop) or
  not white (:meth:`SineFit.ratio`).

``fraction``: the share of each signal's variance about the offset and drift that the
sine holds, ``|Y|^2/2 / var(y - c0 - c1*t)`` (1 for a noise-free linear response; lower
with noise or harmonics).  Used by ``servo bode`` (:mod:`servo.experiments.bode`) and
``servo loop`` (:mod:`servo.loop.measure`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class SineFit:
    """The demodulated amplitudes of ``m`` signals at one frequency: ``amp`` (m,)
    complex (same unit as the signal), ``std`` (m,) each complex component's standard
    error, ``per_period`` (periods, m) complex, ``fraction`` (m,) in [0, 1]."""

    amp: np.ndarray
    std: np.ndarray
    per_period: np.ndarray
    fraction: np.ndarray

    def ratio(self, num: int, den: int) -> tuple[complex, float]:
        """``H = amp[num]/amp[den]`` and its standard deviation (each complex component)
        from the per-period spread, ``std(H_i, ddof=1)/sqrt(periods)`` (NaN for one period)."""
        H = self.amp[num] / self.amp[den]
        Hi = self.per_period[:, num] / self.per_period[:, den]
        p = Hi.size
        return H, (float(np.std(Hi, ddof=1) / math.sqrt(p)) if p > 1 else float("nan"))


def _fit(Y: np.ndarray, w: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitudes ``a - j*b`` (m,) and their standard errors (m,) of the fit of the
    module doc on ``Y`` (n, m) at ``w`` rad/s, times ``t`` (n,) s."""
    tc = t - t.mean()
    A = np.column_stack([np.ones_like(t), tc, np.cos(w * t), np.sin(w * t)])
    coef, *_ = np.linalg.lstsq(A, Y, rcond=None)
    n = t.size
    if n > 4:
        rss = np.sum((Y - A @ coef) ** 2, axis=0)
        try:
            d = np.diag(np.linalg.inv(A.T @ A))
            std = np.sqrt(rss / (n - 4) * 0.5 * (d[2] + d[3]))
        except np.linalg.LinAlgError:
            std = np.full(Y.shape[1], np.nan)
    else:
        std = np.full(Y.shape[1], np.nan)
    return coef[2] - 1j * coef[3], std


def demodulate(Y: np.ndarray, f: float, t: np.ndarray, periods: int) -> SineFit:
    """The complex amplitudes at ``f`` Hz of the columns of ``Y`` ((n, m), or (n,) for
    one signal) over a window of ``periods`` whole periods at times ``t`` ((n,) s, from
    the excitation's phase zero): the least-squares sine fit with offset and drift of
    the module doc, over the whole window and over each period (the window cut at
    ``round(i*n/periods)``)."""
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    t = np.asarray(t, dtype=float)
    n = t.size
    w = 2.0 * np.pi * f
    amp, std = _fit(Y, w, t)
    edges = np.round(np.arange(periods + 1) * n / periods).astype(int)
    per = np.array([_fit(Y[c:b], w, t[c:b])[0] for c, b in zip(edges[:-1], edges[1:])])
    tc = t - t.mean()
    drift = np.column_stack([np.ones_like(t), tc])
    resid = Y - drift @ np.linalg.lstsq(drift, Y, rcond=None)[0]
    var = np.var(resid, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(var > 0, np.minimum(1.0, np.abs(amp) ** 2 / 2.0 / var), 1.0)
    return SineFit(amp, std, per, frac)


__all__ = ["SineFit", "demodulate"]

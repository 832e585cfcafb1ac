"""Frequency-response estimates from sampled signals: H1 over Welch segments, open or
closed loop (the reference as instrument), with coherence and random-error bounds.

Open loop (the input ``u`` is not fed back from the output ``y``)::

    H1(f) = P_uy(f) / P_uu(f)                coherence  g2 = |P_uy|^2 / (P_uu P_yy)

Closed loop, an instrument ``r`` (the reference, or an excitation added in the loop)
that the output noise does not reach::

    H(f) = P_ry(f) / P_ru(f)

Welch averages (``scipy.signal.welch``/``csd``, Hann windows, 50 % overlap by default)
of ``K`` segments.  ``P_xy = E[conj(X) Y]`` (scipy's convention).  Why the instrument:
in a loop, ``u`` carries the output noise fed back through the controller, so ``H1``
is biased towards ``-1/C`` wherever that noise dominates; ``r`` is independent of the
noise and the ratio of its cross-spectra is unbiased (Soderstrom & Stoica, *System
Identification*, 1989, ch. 8; Pintelon & Schoukens, *System Identification: a frequency
domain approach*, 2012, ch. 2 and 6).

**Random error.**  With ``n = y - H u`` the part of the output no input explains (its
spectrum ``P_nn`` estimated from the residual), the estimate is ``H + P_rn/P_ru``
(``r = u`` in open loop), and for ``K_eq`` equivalent independent averages its error is
complex with each component of standard deviation (relative to ``|H|``)::

    rel_std = sqrt( P_nn / (2 K_eq g2_ru P_uu |H|^2) )

In open loop (``g2_ru = 1``, ``P_nn = (1 - g2) P_yy``) this is Bendat & Piersol's
``sqrt(1 - g2) / (|g| sqrt(2 K_eq))`` (*Random Data*, 4th ed., eq. 9.90): the standard
deviation of ``|H|`` relative to ``|H|`` and of the phase in radians.  The reported
``coherence`` is the one that gives the same error in that formula, the input's
share of the output: the ordinary coherence in open loop,
``SNR/(1 + SNR)`` with ``SNR = g2_ru P_uu |H|^2 / P_nn`` in closed loop.
``K_eq = K / (1 + 2 sum_j (1 - j/K) rho_j)`` with ``rho_j`` the squared correlation of
the window with itself shifted by ``j`` hops (Welch 1967; 0.028 for Hann at 50 %), so
overlapping segments are not counted as independent.  The formula is first order: it
holds where the coherence is at least ~0.5 (checked in ``tests/test_frf.py``: the
error exceeds 1 and 3 standard deviations as often as a Rayleigh law says there, on
known systems open and closed loop); below, the ratio of noisy spectra has heavier
tails than it says.  It says nothing of the bias of leakage, which a segment much
longer than the slowest decay of the system keeps small.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from servo.errors import RecordingError
from servo.io.frequency_response import FrequencyResponse

#: averages the default segment length leaves at least
MIN_AVERAGES = 8


@dataclass(frozen=True)
class WelchSettings:
    """Welch segments.  ``nperseg``: samples per segment (default: the largest power of
    two that leaves ``min_averages`` segments); ``overlap``: fraction in [0, 1);
    ``window``: a ``scipy.signal.get_window`` name; ``detrend``: ``constant`` (mean) or
    ``linear`` per segment (for a drifting output)."""

    nperseg: int | None = None
    overlap: float = 0.5
    window: str = "hann"
    detrend: str = "constant"
    min_averages: int = MIN_AVERAGES

    def check(self, n: int) -> "WelchSettings":
        """These settings for ``n`` samples, with the segment length resolved."""
        if not 0 <= self.overlap < 1:
            raise RecordingError(f"frf: overlap {self.overlap!r} must lie in [0, 1)")
        if self.detrend not in ("constant", "linear"):
            raise RecordingError(f"frf: detrend {self.detrend!r}: use constant or linear")
        nper = self.nperseg or default_nperseg(n, self.min_averages, self.overlap)
        if nper < 8:
            raise RecordingError(f"frf: {n} samples are too few for {self.min_averages} Welch segments of at least 8 samples")
        if nper > n:
            raise RecordingError(f"frf: segments of {nper} samples are longer than the recording ({n} samples)")
        try:
            signal.get_window(self.window, 8)
        except ValueError as exc:
            raise RecordingError(f"frf: window {self.window!r}: {exc}") from None
        return WelchSettings(int(nper), self.overlap, self.window, self.detrend, self.min_averages)

    @property
    def noverlap(self) -> int:
        return overlap_samples(self.overlap, self.nperseg)


def overlap_samples(overlap: float, nperseg: int) -> int:
    """Samples two segments of ``nperseg`` share at ``overlap``: rounded, and at most
    ``nperseg - 1`` (an overlap of 0.999999 rounded to the whole segment: no step, exit 70)."""
    return min(int(round(overlap * nperseg)), nperseg - 1)


def n_segments(n: int, nperseg: int, noverlap: int) -> int:
    """Welch segments of ``nperseg`` samples with ``noverlap`` overlap in ``n`` samples."""
    return (n - noverlap) // (nperseg - noverlap)


def default_nperseg(n: int, min_averages: int = MIN_AVERAGES, overlap: float = 0.5) -> int:
    """The largest power of two whose Welch segments number at least ``min_averages``
    in ``n`` samples (the finest resolution that still averages)."""
    nper = 1 << max(int(np.log2(max(n, 1))), 0)
    while nper > 8 and n_segments(n, nper, overlap_samples(overlap, nper)) < min_averages:
        nper //= 2
    return nper


def equivalent_averages(window: np.ndarray, nperseg: int, noverlap: int, K: int) -> float:
    """Independent averages equivalent to ``K`` overlapping windowed segments (Welch 1967)."""
    step = nperseg - noverlap
    w2 = np.sum(window**2)
    s = 0.0
    for j in range(1, K):
        shift = j * step
        if shift >= nperseg:
            break
        rho = (np.sum(window[: nperseg - shift] * window[shift:]) / w2) ** 2
        s += (1 - j / K) * rho
    return K / (1 + 2 * s)


@dataclass
class Spectra:
    """Auto and cross spectra over the Welch segments, shape ``(n_f,)``; ``f`` Hz."""

    f: np.ndarray
    K: int
    K_eq: float
    P: dict = field(default_factory=dict)


def spectra(signals: dict[str, np.ndarray], dt: float, s: WelchSettings, pairs) -> Spectra:
    """Welch auto spectra of every signal and the cross spectra of ``pairs`` ``(a, b)``
    (``P_ab = E[conj(A) B]``), one-sided, same segments for all."""
    fs = 1.0 / dt
    kw = dict(fs=fs, window=s.window, nperseg=s.nperseg, noverlap=s.noverlap, detrend=s.detrend)
    out: dict = {}
    f = None
    for name, x in signals.items():
        f, out[(name, name)] = signal.welch(x, **kw)
    for a, b in pairs:
        _, out[(a, b)] = signal.csd(signals[a], signals[b], **kw)
    n = next(iter(signals.values())).size
    K = n_segments(n, s.nperseg, s.noverlap)
    K_eq = equivalent_averages(signal.get_window(s.window, s.nperseg), s.nperseg, s.noverlap, K)
    return Spectra(f, K, K_eq, out)


def _finish(sp: Spectra, H, g2_ru, Puu, Pyy, Puy, meta: dict, unit: str) -> FrequencyResponse:
    with np.errstate(divide="ignore", invalid="ignore"):
        # residual n = y - H u: P_nn = P_yy - 2 Re(conj(H) P_uy) + |H|^2 P_uu
        Pnn = np.maximum(Pyy - 2 * np.real(np.conj(H) * Puy) + np.abs(H) ** 2 * Puu, 0.0)
        explained = g2_ru * Puu * np.abs(H) ** 2
        snr = explained / Pnn
        coherence = np.where(Pnn > 0, snr / (1 + snr), 1.0)
        rel_std = np.sqrt(Pnn / (2 * sp.K_eq * explained))
    keep = sp.f > 0  # DC: no response to speak of after detrending
    meta = {**meta, "segments": sp.K, "equivalent_averages": sp.K_eq, "resolution_hz": float(sp.f[1] - sp.f[0])}
    return FrequencyResponse(sp.f[keep], H[keep], coherence[keep], rel_std[keep], unit, meta)


def _check_signal(name: str, x: np.ndarray, n: int) -> np.ndarray:
    x = np.asarray(x, dtype=float).ravel()
    if x.size != n:
        raise RecordingError(f"frf: {name} has {x.size} samples, the input {n}")
    if not np.all(np.isfinite(x)):
        raise RecordingError(f"frf: {name} is NaN or infinite at sample {int(np.flatnonzero(~np.isfinite(x))[0])}")
    if np.ptp(x) == 0:
        raise RecordingError(f"frf: {name} is constant: it excites nothing")
    return x


def h1(u: np.ndarray, y: np.ndarray, dt: float, settings: WelchSettings | None = None, unit: str = "") -> FrequencyResponse:
    """Open-loop H1 estimate of the response from ``u`` to ``y`` (arrays ``(n,)``,
    sample period ``dt`` s) with coherence and ``rel_std``; ``unit`` names the result's
    unit (e.g. ``m/A``).  Frequencies ``k/(nperseg*dt)``, DC excluded."""
    u = _check_signal("the input", u, np.size(u))
    y = _check_signal("the output", y, u.size)
    s = (settings or WelchSettings()).check(u.size)
    sp = spectra({"u": u, "y": y}, dt, s, [("u", "y")])
    Puu, Pyy, Puy = sp.P[("u", "u")], sp.P[("y", "y")], sp.P[("u", "y")]
    with np.errstate(divide="ignore", invalid="ignore"):
        H = Puy / Puu
    meta = {"method": "H1 (open loop)", "nperseg": s.nperseg, "overlap": s.overlap, "window": s.window,
            "detrend": s.detrend}  # fmt: skip
    return _finish(sp, H, np.ones_like(Puu), Puu, Pyy, Puy, meta, unit)


def instrumental(r: np.ndarray, u: np.ndarray, y: np.ndarray, dt: float, settings: WelchSettings | None = None,
                 unit: str = "") -> FrequencyResponse:  # fmt: skip
    """Closed-loop estimate ``P_ry/P_ru`` of the response from ``u`` to ``y`` with the
    instrument ``r`` (the reference, or an excitation injected in the loop; arrays
    ``(n,)``, ``dt`` s).  ``meta`` gets the coherences ``coherence_ru`` and
    ``coherence_ry`` (lists, same frequencies)."""
    u = _check_signal("the input", u, np.size(u))
    y = _check_signal("the output", y, u.size)
    r = _check_signal("the instrument (reference)", r, u.size)
    s = (settings or WelchSettings()).check(u.size)
    sp = spectra({"r": r, "u": u, "y": y}, dt, s, [("r", "u"), ("r", "y"), ("u", "y")])
    P = sp.P
    Prr, Puu, Pyy = P[("r", "r")], P[("u", "u")], P[("y", "y")]
    with np.errstate(divide="ignore", invalid="ignore"):
        H = P[("r", "y")] / P[("r", "u")]
        g2_ru = np.abs(P[("r", "u")]) ** 2 / (Prr * Puu)
        g2_ry = np.abs(P[("r", "y")]) ** 2 / (Prr * Pyy)
    keep = sp.f > 0
    meta = {"method": "instrumental (closed loop, reference as instrument)", "nperseg": s.nperseg,
            "overlap": s.overlap, "window": s.window, "detrend": s.detrend,
            "coherence_ru": g2_ru[keep].tolist(), "coherence_ry": g2_ry[keep].tolist()}  # fmt: skip
    return _finish(sp, H, g2_ru, Puu, Pyy, P[("u", "y")], meta, unit)


__all__ = ["MIN_AVERAGES", "WelchSettings", "default_nperseg", "equivalent_averages", "h1", "instrumental", "n_segments",
           "spectra"]  # fmt: skip

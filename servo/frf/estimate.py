"""The project's one frequency-response estimator: H1 over Welch segments, open or
closed loop (the reference as instrument), with one coherence and one random-error
formula.  ``servo frf`` (:mod:`servo.frf.job`), ``servo diagnose``'s frequency path
(:mod:`servo.diagnose.frf_modes`, which chooses the segments: those in which the arm
slides) and the holding-loop check of ``servo bode`` read their spectra here; ``servo
loop`` and ``servo bode`` measure with a stepped sine instead (:mod:`servo.frf.sine`).

Open loop (the input ``u`` is not fed back from the output ``y``)::

    H1(f) = P_uy(f) / P_uu(f)                coherence  g2 = |P_uy|^2 / (P_uu P_yy)

Closed loop, an instrument ``r`` (the reference, or an excitation added in the loop)
that the output noise does not reach::

    H(f) = P_ry(f) / P_ru(f)

Welch averages (Hann windows, 50 % overlap by default) of ``K`` segments, computed
with scipy's own arithmetic (:func:`spectra`: ``scipy.signal.ShortTimeFFT``'s scaled
window and ``csd``'s steps, so that on all the segments the result is
``scipy.signal.csd``/``welch``'s to the bit), or of the segments a caller chooses.  ``P_xy = E[conj(X) Y]`` (scipy's convention).  Why the instrument:
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
share of the output, ``E/(E + P_nn)`` with ``E = g2_ru P_uu |H|^2``: the ordinary
coherence ``|P_uy|^2/(P_uu P_yy)`` in open loop, ``SNR/(1 + SNR)`` with ``SNR = E/P_nn``
in closed loop (``g2_ru`` the instrument's ordinary coherence with the input).
``K_eq = K / (1 + (2/K) sum_j N_j rho_j)`` with ``rho_j`` the squared correlation of
the window with itself shifted by ``j`` hops (Welch 1967; 0.028 for Hann at 50 %) and
``N_j`` the pairs of segments used that lie ``j`` hops apart (``K - j`` when every
segment is used), so overlapping segments are not counted as independent.  The formula is first order: it
holds where the coherence is at least ~0.5 (checked in ``tests/test_frf.py``: the
error exceeds 1 and 3 standard deviations as often as a Rayleigh law says there, on
known systems open and closed loop); below, the ratio of noisy spectra has heavier
tails than it says.  It says nothing of the bias of leakage, which a segment much
longer than the slowest decay of the system keeps small.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sp_fft
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
    ``linear`` per segment (for a drifting output), or ``none`` (:func:`psd` only; ``servo
    frf`` refuses it)."""

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


def segment_starts(n: int, nperseg: int, noverlap: int) -> np.ndarray:
    """First samples of the Welch segments of ``nperseg`` samples with ``noverlap``
    overlap in ``n`` samples (scipy's segments: from sample 0, every ``nperseg -
    noverlap``), shape ``(n_segments(n, nperseg, noverlap),)``."""
    return np.arange(n_segments(n, nperseg, noverlap), dtype=np.int64) * (nperseg - noverlap)


def equivalent_averages(window: np.ndarray, nperseg: int, noverlap: int, K: int,
                        starts: np.ndarray | None = None) -> float:  # fmt: skip
    """Independent averages equivalent to ``K`` overlapping windowed segments (Welch 1967).

    ``K_eq = K / (1 + (2/K) sum_j N_j rho_j)``: ``rho_j`` the squared correlation of the
    window with itself shifted by ``j`` hops, ``N_j`` the pairs of segments ``j`` hops
    apart.  ``starts`` (the segments used, when some were left out): ``N_j`` counted
    among them; None: ``K`` consecutive segments, ``N_j = K - j``."""
    step = nperseg - noverlap
    w2 = np.sum(window**2)
    s = 0.0
    for j in range(1, K):
        shift = j * step
        if shift >= nperseg:
            break
        rho = (np.sum(window[: nperseg - shift] * window[shift:]) / w2) ** 2
        if starts is None:
            s += (1 - j / K) * rho
        else:
            s += int(np.count_nonzero(np.isin(starts + shift, starts))) / K * rho
    return K / (1 + 2 * s)


@dataclass
class Spectra:
    """Auto and cross spectra over the Welch segments, shape ``(n_f,)``, one-sided, per
    Hz (``P[(a, b)] = E[conj(A) B]``); ``f`` Hz; ``K`` segments averaged, ``K_eq`` their
    equivalent independent averages."""

    f: np.ndarray
    K: int
    K_eq: float
    P: dict = field(default_factory=dict)


def frequencies(nperseg: int, dt: float) -> np.ndarray:
    """The Welch grid of segments of ``nperseg`` samples, ``k/(nperseg*dt)`` Hz, DC
    included, shape ``(nperseg//2 + 1,)``."""
    return sp_fft.rfftfreq(nperseg, dt)


#: segments transformed at once when only some are used (the spectra of a 1e6-sample
#: recording's segments need not all be held)
CHUNK = 64


def spectra(signals: dict[str, np.ndarray], dt: float | None, s: WelchSettings, pairs,
            starts: np.ndarray | None = None, fs: float | None = None) -> Spectra:  # fmt: skip
    """Welch auto spectra of every signal and the cross spectra of ``pairs`` ``(a, b)``
    (``P_ab = E[conj(A) B]``), one-sided, per Hz, same segments for all: each segment
    detrended (``s.detrend``), windowed, transformed once, the products averaged.  The
    result is ``scipy.signal.csd``/``welch``'s (``scaling="density"``,
    ``average="mean"``; ``tests/test_frf_estimator.py`` checks it).
    ``starts`` (int array): the first sample of each segment to use (segments of
    ``s.nperseg`` samples, multiples of the hop, e.g. only those in which the arm
    slides); None: every segment, as scipy.  ``fs`` (Hz), instead of ``dt``: the sample
    rate as a caller of scipy has it (``1/(1/fs)`` is not always ``fs``)."""
    x0 = next(iter(signals.values()))
    n, nper, nov = x0.size, s.nperseg, s.noverlap
    all_starts = segment_starts(n, nper, nov)
    sel = all_starts if starts is None else np.asarray(starts, dtype=np.int64)
    hop = nper - nov
    if np.any(sel % hop) or np.any(sel < 0) or np.any(sel + nper > n):
        raise ValueError("spectra: segment starts must be multiples of the hop inside the signal")
    f = frequencies(nper, dt) if fs is None else None
    fs = 1.0 / dt if fs is None else fs
    w = signal.get_window(s.window, nper)
    # scipy.signal.csd's own arithmetic, operation for operation (ShortTimeFFT's scaled
    # window and frequencies, each segment detrended, windowed and transformed as
    # ShortTimeFFT.stft_detrend does, the products in its layout, the one-sided
    # doubling, numpy's mean over the segments), so that ``servo frf`` reads scipy's
    # numbers to the bit; the segments are transformed together (scipy's loop takes
    # one at a time), and with ``starts`` a chunk at a time, only those kept
    sft = signal.ShortTimeFFT(w, hop, fs, fft_mode="onesided", mfft=nper, scale_to="psd", phase_shift=None)
    f = sft.f if f is None else f
    win = sft.win
    names = list(signals)
    keys = [(a, a) for a in names] + list(pairs)
    parts: dict = {key: [] for key in keys}
    chunk = max(sel.size, 1) if starts is None else CHUNK  # every segment: at once, as scipy (numpy's
    for c in range(0, sel.size, chunk):  # complex product rounds by position in the array)
        idx = sel[c : c + chunk, None] + np.arange(nper)[None, :]
        S = {}
        for a in names:
            fr = np.asarray(signals[a], dtype=float)[idx]
            if s.detrend == "constant":
                fr = fr - np.mean(fr, axis=-1, keepdims=True)
            elif s.detrend == "linear":  # one segment at a time: scipy's batched fit rounds otherwise
                fr = np.array([signal.detrend(row, type="linear") for row in fr])
            S[a] = np.ascontiguousarray(sp_fft.rfft(fr * win, n=nper, axis=-1).T)  # (n_f, k), scipy's layout
        for a, b in keys:
            P = S[a].real ** 2 + S[a].imag ** 2 if a == b else S[b] * S[a].conj()  # E[conj(A) B]
            P[1 : (-1 if nper % 2 == 0 else None)] *= 2  # one-sided; the Nyquist bin has no twin
            parts[(a, b)].append(P)
    K = int(sel.size)
    out: dict = {}
    for (a, b), chunks in parts.items():
        if not K:
            out[(a, b)] = np.zeros(f.size, float if a == b else complex)
            continue
        P = np.ascontiguousarray(np.concatenate(chunks, axis=-1)).mean(axis=-1).astype(complex)  # scipy's layout
        out[(a, b)] = P.real if a == b else P
    K_eq = equivalent_averages(w, nper, nov, K, None if starts is None else sel) if K else 0.0
    return Spectra(f, K, K_eq, out)


def ordinary_coherence(Pab: np.ndarray, Paa: np.ndarray, Pbb: np.ndarray) -> np.ndarray:
    """The ordinary (magnitude-squared) coherence ``|P_ab|^2 / (P_aa P_bb)`` of two
    signals from their spectra, in scipy's arithmetic (``scipy.signal.coherence``)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(Pab) ** 2 / Paa / Pbb


def _plain(nperseg: int, n: int, overlap: float | None, window: str, detrend: str) -> WelchSettings:
    nper = min(int(nperseg), n)  # scipy shortens a segment longer than the signal
    return WelchSettings(nper, (nper // 2) / nper if overlap is None else overlap, window, detrend)


def psd(x: np.ndarray, fs: float, nperseg: int, overlap: float | None = None, window: str = "hann",
        detrend: str = "constant") -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The Welch power spectral density of ``x`` ((n,), sampled at ``fs`` Hz): ``(f,
    P)``, each ``(nperseg//2 + 1,)``, one-sided, per Hz (unit of ``x`` squared per Hz);
    overlap None: ``nperseg//2`` samples.  ``scipy.signal.welch``'s numbers on the same
    settings (:func:`spectra`)."""
    x = np.asarray(x, dtype=float)
    sp = spectra({"x": x}, None, _plain(nperseg, x.size, overlap, window, detrend), [], fs=fs)
    return sp.f, sp.P[("x", "x")]


def coherence(a: np.ndarray, b: np.ndarray, fs: float, nperseg: int, overlap: float | None = None,
              window: str = "hann", detrend: str = "constant") -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The ordinary coherence of ``a`` and ``b`` ((n,) each, sampled at ``fs`` Hz) over Welch
    segments: ``(f, C)`` (:func:`ordinary_coherence`; ``scipy.signal.coherence``'s
    numbers on the same settings)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    sp = spectra({"a": a, "b": b}, None, _plain(nperseg, a.size, overlap, window, detrend), [("a", "b")], fs=fs)
    return sp.f, ordinary_coherence(sp.P[("a", "b")], sp.P[("a", "a")], sp.P[("b", "b")])


@dataclass
class Estimate:
    """The one frequency-response estimate (module doc), every bin of the Welch grid
    (DC included), shape ``(n_f,)``: ``f`` Hz, ``H`` complex, ``coherence`` the input's
    share of the output ``E/(E + P_nn)``, ``rel_std`` each complex component's standard
    deviation relative to ``|H|``, ``g2_ru`` the instrument's ordinary coherence with
    the input (1 in open loop), ``g2_ry`` its coherence with the output (the output's
    own in open loop, ``|P_uy|^2/(P_uu P_yy)``), ``Puu`` the input's spectrum (per Hz),
    ``K``/``K_eq`` segments and their equivalent independent averages, ``method``
    ``"H1"`` or ``"instrumental"``."""

    f: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    rel_std: np.ndarray
    g2_ru: np.ndarray
    g2_ry: np.ndarray
    Puu: np.ndarray
    K: int
    K_eq: float
    method: str


def estimate(sp: Spectra, u: str = "u", y: str = "y", r: str | None = None) -> Estimate:
    """The response from ``u`` to ``y`` from the spectra ``sp`` (:func:`spectra`, with the
    pairs ``(u, y)``, and ``(r, u)``, ``(r, y)`` for an instrument): ``H1 = P_uy/P_uu``
    without ``r``, ``P_ry/P_ru`` with it; coherence and ``rel_std`` by the module doc's
    one formula (Bendat & Piersol eq. 9.90 in open loop)."""
    P = sp.P
    Puu, Pyy, Puy = P[(u, u)], P[(y, y)], P[(u, y)]
    with np.errstate(divide="ignore", invalid="ignore"):
        if r is None:
            H = Puy / Puu
            g2_ru = np.ones_like(Puu)
            g2_ry = ordinary_coherence(Puy, Puu, Pyy)
        else:
            Prr = P[(r, r)]
            H = P[(r, y)] / P[(r, u)]
            g2_ru = ordinary_coherence(P[(r, u)], Prr, Puu)
            g2_ry = ordinary_coherence(P[(r, y)], Prr, Pyy)
        # residual n = y - H u: P_nn = P_yy - 2 Re(conj(H) P_uy) + |H|^2 P_uu
        Pnn = np.maximum(Pyy - 2 * np.real(np.conj(H) * Puy) + np.abs(H) ** 2 * Puu, 0.0)
        explained = g2_ru * Puu * np.abs(H) ** 2
        snr = explained / Pnn
        coherence = np.where(Pnn > 0, snr / (1 + snr), 1.0)
        rel_std = np.sqrt(Pnn / (2 * sp.K_eq * explained))
    method = "H1" if r is None else "instrumental"
    return Estimate(sp.f, H, coherence, rel_std, g2_ru, g2_ry, Puu, sp.K, sp.K_eq, method)


def window_kernel(window: str, nperseg: int, res: int = 4, half: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """The power kernel of a Welch window of ``nperseg`` samples: what a Welch estimate
    reads of a response that varies across a bin is its average over this kernel.
    Offsets (bins, ``res`` per bin, ``-half .. half`` bins) and weights summing to 1,
    shape ``(2*half*res + 1,)`` each."""
    w = signal.get_window(window, nperseg)
    m = nperseg * res
    W = np.abs(np.fft.fft(w, m)) ** 2
    k = np.arange(-half * res, half * res + 1)
    wt = W[k % m]
    return k / res, wt / wt.sum()


def _finish(sp: Spectra, est: Estimate, meta: dict, unit: str) -> FrequencyResponse:
    keep = sp.f > 0  # DC: no response to speak of after detrending
    meta = {**meta, "segments": sp.K, "equivalent_averages": sp.K_eq, "resolution_hz": float(sp.f[1] - sp.f[0])}
    return FrequencyResponse(sp.f[keep], est.H[keep], est.coherence[keep], est.rel_std[keep], unit, meta)


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
    meta = {"method": "H1 (open loop)", "nperseg": s.nperseg, "overlap": s.overlap, "window": s.window,
            "detrend": s.detrend}  # fmt: skip
    return _finish(sp, estimate(sp), meta, unit)


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
    est = estimate(sp, r="r")
    keep = sp.f > 0
    meta = {"method": "instrumental (closed loop, reference as instrument)", "nperseg": s.nperseg,
            "overlap": s.overlap, "window": s.window, "detrend": s.detrend,
            "coherence_ru": est.g2_ru[keep].tolist(), "coherence_ry": est.g2_ry[keep].tolist()}  # fmt: skip
    return _finish(sp, est, meta, unit)


__all__ = ["MIN_AVERAGES", "Estimate", "Spectra", "WelchSettings", "coherence", "default_nperseg", "equivalent_averages",
           "estimate", "frequencies", "h1", "instrumental", "n_segments", "ordinary_coherence", "psd", "segment_starts",
           "spectra", "window_kernel"]  # fmt: skip

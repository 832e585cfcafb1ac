"""Where the input has power: the band over which the recorded motion stands above the
position sensor's noise, and the decimation whose rows cover it.

The input's power reaches the force balance only through the measured motion: at a
frequency where the input moves the arm by less than the sensor's noise, the rows'
acceleration is the noise's second difference and the balance there holds nothing but
noise (in a closed loop the input may have much power there, the controller's answer
to that noise).  So the band is read from the measured motion, as the rows read it: the
Welch spectrum (:func:`servo.frf.estimate.psd`, scipy's numbers, Hann segments of :func:`nperseg`, no
detrend: a line fitted to a segment leaks into its lowest bins) of the position's second
difference, against what the position sensor's white noise of std ``sigma_x`` (the rows'
estimate, ``noise_x`` of :class:`servo.diagnose.signals.Signals`) gives through it,
``2*sigma_x^2/fs * (2*sin(pi*f/fs))^4`` (one-sided, (m/sample^2)^2/Hz; as the window
reads it, :func:`signal_to_noise`).  The ratio is the
position's signal to noise at each frequency; the second difference only flattens the
spectrum first: the position's own spectrum spans 120 dB on the proving ground (1 mm
strokes, nm noise), and a Hann window's side lobes carried the slow motion's power 20 dB
over the floor up to 0.05*fs on chirps and multisines whose second difference stands
there under it.  The **power edge** is the highest frequency whose bin stands
:data:`MARGIN_DB` over that floor (20 dB, fixed on development recordings before any
scoring; a Welch bin of the noise alone, at least 16 segments' worth at 50 % overlap,
stays under 3 x the floor with probability 1 - 1e-6).  The rows' band ``0.4*fs/q``
(:func:`servo.diagnose.band.band_hz`) covers it for every ``q <= 0.4*fs/edge``;
:func:`decimation_for` takes the largest such ``q`` of the candidates (the most
averaging that still covers the power), the largest candidate where the power ends
inside its band, the smallest where no candidate covers it.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from servo.frf.estimate import psd

#: the position must stand this far over the sensor's white noise floor (dB of power)
MARGIN_DB = 20.0
#: Welch segment length bounds (samples): the longest power of two leaving 16 segments
NPERSEG_MAX = 4096
NPERSEG_MIN = 64
SEGMENTS = 16


def nperseg(n: int) -> int:
    """Welch segment length for ``n`` samples: the largest power of two up to
    :data:`NPERSEG_MAX` that leaves at least :data:`SEGMENTS` segments (at least
    :data:`NPERSEG_MIN`)."""
    k = int(math.floor(math.log2(max(n / SEGMENTS, 1.0))))
    return int(min(NPERSEG_MAX, max(NPERSEG_MIN, 1 << k)))


def signal_to_noise(x: np.ndarray, fs: float, noise_x: float) -> tuple[np.ndarray, np.ndarray]:
    """``(f, ratio)``: the Welch spectrum of the second difference of the position ``x``
    (m, ``(n,)``) over that of a white position noise of std ``noise_x`` (m) at the
    frequencies ``f`` (Hz), each ``(nperseg/2 + 1,)`` (module doc; the ratio at 0 Hz,
    where both vanish, is set to 0)."""
    d = np.diff(np.asarray(x, dtype=float), 2)
    m = min(nperseg(d.size), d.size)
    f, P = psd(d, fs, m, detrend="none")  # a fitted line leaks into the lowest bins
    # the noise's expected Welch estimate: its second difference's autocovariance
    # sigma^2*(6, -4, 1) at lags 0, 1, 2 seen through the window's (c_k = sum w_n w_n+k),
    # not (2 sin(w/2))^4 itself, which the window's leakage exceeds at low frequencies
    w = signal.get_window("hann", m)
    c = [float(np.dot(w[: m - k], w[k:])) for k in range(3)]
    wk = 2 * np.pi * f / fs
    floor = 2.0 * noise_x**2 / fs * (6 * c[0] - 8 * c[1] * np.cos(wk) + 2 * c[2] * np.cos(2 * wk)) / c[0]
    ratio = np.zeros_like(P)
    ratio[1:] = P[1:] / floor[1:]
    return f, ratio


def edge_hz(x: np.ndarray, fs: float, noise_x: float, margin_db: float = MARGIN_DB) -> float:
    """The power edge (Hz, module doc): the highest frequency where the position stands
    ``margin_db`` over a white noise of std ``noise_x`` (m); 0 where it nowhere does,
    ``fs/2`` with no noise at all."""
    if not noise_x > 0:
        return 0.5 * fs
    f, ratio = signal_to_noise(x, fs, noise_x)
    above = np.flatnonzero(ratio > 10.0 ** (margin_db / 10.0))
    return float(f[above[-1]]) if above.size else 0.0


def decimation_for(edge: float, fs: float, candidates) -> int:
    """The largest of ``candidates`` whose rows' band ``0.4*fs/q`` reaches ``edge`` (Hz);
    the smallest candidate when none does."""
    ok = [int(q) for q in candidates if 0.4 * fs / q >= edge]
    return max(ok) if ok else min(int(q) for q in candidates)


__all__ = ["MARGIN_DB", "decimation_for", "edge_hz", "nperseg", "signal_to_noise"]

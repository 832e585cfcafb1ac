"""Excitation signals for frequency-response measurements: chirp, multisine, PRBS.

Pure functions of the sample count ``n``, the sample period ``dt`` (s) and their
parameters; each returns a float64 array of shape ``(n,)`` whose peak magnitude is
``amplitude`` (the unit of what it excites: A for a current, m for a reference), so an
actuator's limit is respected by construction.  A scenario adds one to the reference or
to the holding loop's output; ``servo frf`` estimates the response from the recording.

Which to choose:

* :func:`chirp` -- a swept sine, ``f0`` to ``f1`` over the record; log sweep by default
  (equal time per decade: power spectral density ~ 1/f).  Not periodic: estimate with
  Welch segments, and keep each segment long against the sweep rate.
* :func:`multisine` -- a sum of equal-amplitude sines on the lines ``k/(period*dt)``
  within ``[f_min, f_max]``, Schroeder phases (crest factor ~1.5-1.8 instead of ~3-4 for
  random phases).  Periodic with ``period`` samples: with Welch segments of that length
  (or multiples) there is no leakage and the power sits only on the chosen lines.
* :func:`prbs` -- a maximum-length binary sequence (``scipy.signal.max_len_seq``),
  ``+-amplitude``, each bit held ``hold`` samples.  The lowest crest factor (1), a flat
  spectrum over one period ``(2**nbits - 1)*hold`` samples up to about
  ``0.44/(hold*dt)`` Hz (the first null of its ``sinc^2`` envelope is at ``1/(hold*dt)``).
"""
from __future__ import annotations

import numpy as np

from servo.errors import ConfigError


class ExcitationError(ConfigError, ValueError):
    """Parameters no signal can meet (one line; a ``ValueError`` for library callers)."""


def _check(n: int, dt: float, amplitude: float) -> None:
    if int(n) != n or n < 1:
        raise ExcitationError(f"n must be a positive whole number of samples, got {n!r}")
    if not dt > 0:
        raise ExcitationError(f"dt must be positive (s), got {dt!r}")
    if not amplitude > 0:
        raise ExcitationError(f"amplitude must be positive, got {amplitude!r}")


def _nyquist_check(dt: float, *freqs: float) -> None:
    fn = 0.5 / dt
    for f in freqs:
        if not 0 < f < fn:
            raise ExcitationError(f"frequency {f!r} Hz must lie in (0, {fn:g}) Hz, the Nyquist band of dt = {dt:g} s")


def chirp(n: int, dt: float, f0: float, f1: float, amplitude: float = 1.0, method: str = "logarithmic") -> np.ndarray:
    """Swept sine ``amplitude*cos(phase(t))`` from ``f0`` Hz at ``t = 0`` to ``f1`` Hz at
    the last sample (``scipy.signal.chirp``; ``method``: ``logarithmic`` or ``linear``,
    ``quadratic``, ``hyperbolic``).  Shape ``(n,)``."""
    _check(n, dt, amplitude)
    _nyquist_check(dt, f0, f1)
    t = np.arange(n) * dt
    t1 = max(t[-1], dt)
    from scipy import signal  # imported where used: a run without a chirp or a PRBS starts without it

    return amplitude * signal.chirp(t, f0=f0, t1=t1, f1=f1, method=method)


def multisine_lines(period: int, dt: float, f_min: float, f_max: float, every: int = 1) -> np.ndarray:
    """The DFT lines (indices ``k`` of ``k/(period*dt)`` Hz) a multisine of
    :func:`multisine` excites: every ``every``-th line from the first at or above
    ``f_min`` to the last at or below ``f_max`` (and below Nyquist).  Shape ``(K,)``."""
    df = 1.0 / (period * dt)
    lo = max(1, int(np.ceil(f_min / df - 1e-9)))
    hi = min(int(np.floor(f_max / df + 1e-9)), (period - 1) // 2)
    return np.arange(lo, hi + 1, int(every))


def multisine(n: int, dt: float, f_min: float, f_max: float, amplitude: float = 1.0, period: int | None = None,
              every: int = 1) -> np.ndarray:  # fmt: skip
    """Periodic multisine with Schroeder phases, peak ``amplitude``.  Shape ``(n,)``.

    One period is ``period`` samples (default ``n``; ``n`` need not be a multiple: the
    signal just repeats); it holds equal-amplitude cosines on the lines
    :func:`multisine_lines` ``(period, dt, f_min, f_max, every)`` with phases
    ``phi_k = -pi*k*(k-1)/K`` (Schroeder 1970, k = 1..K), which keep the crest factor
    low.  The period is built by one inverse FFT, so it is exactly periodic and exactly
    zero on the other lines."""
    period = int(n if period is None else period)
    _check(n, dt, amplitude)
    _check(period, dt, amplitude)
    _nyquist_check(dt, f_min, f_max)
    if f_min > f_max:
        raise ExcitationError(f"f_min {f_min!r} Hz is above f_max {f_max!r} Hz")
    lines = multisine_lines(period, dt, f_min, f_max, every)
    if lines.size == 0:
        raise ExcitationError(f"no line of a {period}-sample period ({1 / (period * dt):g} Hz apart) lies in "
                         f"[{f_min:g}, {f_max:g}] Hz: lengthen the period or widen the band")  # fmt: skip
    K = lines.size
    k = np.arange(1, K + 1)
    spec = np.zeros(period // 2 + 1, complex)
    spec[lines] = np.exp(1j * (-np.pi * k * (k - 1) / K))
    one = np.fft.irfft(spec, period)
    one *= amplitude / np.max(np.abs(one))
    return np.resize(one, n)


def prbs(n: int, dt: float, amplitude: float = 1.0, nbits: int = 10, hold: int = 1, state=None) -> np.ndarray:
    """Maximum-length pseudo-random binary sequence, values ``+-amplitude``.  Shape ``(n,)``.

    ``nbits`` sets the period, ``2**nbits - 1`` bits (``scipy.signal.max_len_seq``, with
    its default taps; ``state``: the initial register, default all ones); each bit is held
    for ``hold`` samples, so the period is ``(2**nbits - 1)*hold`` samples and the lines
    ``1/(period*dt)`` Hz apart; the sequence repeats to fill ``n``.  Over one period the
    spectrum is flat on every line but DC (the two-valued circular autocorrelation) times
    the ``sinc^2`` envelope of the hold.  ``dt`` only checks the arguments (the sequence
    is defined in samples)."""
    _check(n, dt, amplitude)
    if int(hold) != hold or hold < 1:
        raise ExcitationError(f"hold must be a positive whole number of samples, got {hold!r}")
    if int(nbits) != nbits or not 2 <= nbits <= 32:
        raise ExcitationError(f"nbits must be a whole number in [2, 32], got {nbits!r}")
    from scipy import signal

    bits = signal.max_len_seq(int(nbits), state=state)[0]
    one = np.repeat(np.where(bits > 0, amplitude, -amplitude), int(hold)).astype(float)
    return np.resize(one, n)


#: A PRBS flat to ``f_max`` Hz (within about 3 dB: its ``sinc^2`` envelope) holds each bit
#: ``PRBS_BIT_HZ/f_max`` s.
PRBS_BIT_HZ = 0.44


def prbs_period(nbits: int, hold: int = 1) -> int:
    """Samples in one period of :func:`prbs`: ``(2**nbits - 1)*hold``."""
    return (2 ** int(nbits) - 1) * int(hold)


__all__ = ["PRBS_BIT_HZ", "ExcitationError", "chirp", "multisine", "multisine_lines", "prbs", "prbs_period"]

"""Rows of a delayed force for many delays, filtering the recording once.

The ``time_delay`` candidate is scored over some 40 delays (quarter samples up to two
samples either way, whole samples up to ``2q``).  Each delay's rows are the force of the
delayed input (``np.interp`` of the input at ``k - shift``,
:meth:`servo.physics.time_delay.Delay.transform`) through the rows' whole chain: the
alignment, the position's zero-phase Butterworth, the zero-phase Chebyshev and the
decimation (:meth:`servo.diagnose.signals.Signals.force_rows`): two zero-phase filters
over every full-rate sample per delay, 1.5-2 s of a 10 s diagnosis at 1 000 000 samples.

Every step of that chain is linear and time-invariant, and linear interpolation at
``k - shift`` is a linear combination of two whole-sample shifts, so the chain commutes
with the delay: the rows of the delayed force are the undelayed force, filtered once at
full rate, interpolated at ``keep - shift``.  That holds wherever the filters' start-up
at the ends of the recording (and of the trimmed segment the Chebyshev runs over) has
died out; within :data:`EDGE_ROWS` rows of either end the rows are computed by the
exact chain on a piece of the recording long enough (:data:`SETTLE_ROWS` more rows)
for the start-up at the piece's cut to die out below rounding.  The rows then equal the
exact chain's to rounding (relative 1e-13 of the force's peak, tested), and a delay's
rows cost a few milliseconds.
"""
from __future__ import annotations

import numpy as np
from scipy import signal

from servo.diagnose.signals import Signals, align, cheby_sos

#: rows at each end computed by the exact chain (the interior interpolation differs from
#: it by up to 7 % of the force's peak within ~110 rows of an end, by rounding beyond)
EDGE_ROWS = 300
#: further rows of recording beyond the edge rows in each exact piece, for the filters'
#: start-up at the piece's cut to die out
SETTLE_ROWS = 400


def interp_at(u: np.ndarray, k: np.ndarray, shift: float) -> np.ndarray:
    """``u`` (sampled at indices ``k``, floats) at ``k - shift``, clamped at the ends: the
    delay transform of :class:`servo.diagnose.terms.TimeDelay`."""
    return np.interp(k - shift, k, u)


class DelayedForce:
    """Rows (m,) of the force of ``u`` (n,) delayed by ``shift`` samples, for any shift
    within ``max_shift`` samples either way (``rows(shift)``)."""

    def __init__(self, sig: Signals, u: np.ndarray, max_shift: float):
        s = sig.settings
        self.sig, self.u, self.max_shift = sig, u, float(max_shift)
        q = s.decimate
        self.sos = cheby_sos(s.decimate_order, s.decimate_ripple_db, q) if q > 1 else None
        self.pad = 3 * s.decimate_order
        self.piece = s.trim_start + (EDGE_ROWS + SETTLE_ROWS) * q + int(np.ceil(max_shift)) + 2
        #: whether the recording is long enough for the interior path (else every delay
        #: goes through the exact chain)
        self.usable = q > 1 and sig.m > 2 * EDGE_ROWS + 10 and sig.n > 3 * self.piece
        if self.usable:
            self.G = self._cheby(sig.force(u))  # the force filtered once, full rate

    def _cheby(self, z: np.ndarray) -> np.ndarray:
        return signal.sosfiltfilt(self.sos, z, padlen=min(self.pad, z.size - 1))

    def _exact(self, shift: float) -> np.ndarray:
        sig = self.sig
        k = np.arange(sig.n, dtype=float)
        return sig.force_rows(interp_at(self.u, k, shift))

    def rows(self, shift: float) -> np.ndarray:
        """Rows of the force of ``u`` delayed by ``shift`` samples (m,)."""
        if not self.usable:
            return self._exact(shift)
        sig, s = self.sig, self.sig.settings
        n, L, keep = sig.n, self.piece, sig.keep
        out = np.interp(keep - shift, np.arange(n, dtype=float), self.G)
        # the first rows: the exact chain on the first L samples
        k = np.arange(L, dtype=float)
        f = sig.butter(align(interp_at(self.u[:L], k, shift)))
        head = self._cheby(f[s.trim_start :])
        out[:EDGE_ROWS] = head[keep[:EDGE_ROWS] - s.trim_start]
        # the last rows: the exact chain on the last L samples (ending where the recording does)
        k = np.arange(n - L, n, dtype=float)
        f = sig.butter(align(interp_at(self.u[n - L :], k, shift)))
        tail = self._cheby(f[: L - s.trim_end])
        out[-EDGE_ROWS:] = tail[keep[-EDGE_ROWS:] - (n - L)]
        return out


__all__ = ["EDGE_ROWS", "SETTLE_ROWS", "DelayedForce", "interp_at"]

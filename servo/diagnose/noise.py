"""The position sensor's noise, estimated from what the input does not drive.

The rows' noise floor (:mod:`servo.diagnose.verdict`) and the speed below which the
direction of motion is uncertain (:mod:`servo.diagnose.signals`) both need the sensor
noise's power *in the rows' band*, where the motion is too.  Reading it from "what the
Butterworth removes" (the position above ``fs/10``) counts as noise every motion the
input drives up there (a PRBS: 11-21 x the true noise on the proving ground's
open-loop nulls) and extrapolates the spectrum above ``fs/10`` flat into the band (a
pink or low-pass noise: 0.15-0.5 x).

**The method.**  The force balance of eq. (3), with the coefficients fitted on the
usable rows, is applied at the full sample rate to the *recorded* position, not the
filtered one::

    e[k] = J*D2(x)[k] + B*D(x)[k] + K*x[k] + h0 + Fc*s[k] - (u[k-1] + u[k])/2

(``D2`` the three-point second difference, exact for a zero-order-hold input, ``D``
the rows' central difference, ``s`` the sign of the filtered velocity, zero where the
direction is uncertain so that a stuck arm's noise does not switch the friction).
Whatever the input drives, in a loop or not, cancels in ``e``: the second difference of
a mass's motion *is* the held force over ``J``, at every frequency.  What is left is
the sensor noise through ``J*D2`` (``B``, ``K`` add under 1e-3 of it above the rows'
band) plus the model's misfit, which the rows test.  Above the rows' band (from its
edge ``0.4*fs/q`` to ``0.45*fs``) the rows test nothing, and the noise through
``D2`` rises as ``f^4`` over any misfit of the force balance there; so the noise's
spectrum is read there: the Welch PSD of ``e`` (the project's estimator,
:func:`servo.frf.estimate.psd`) over ``J^2 |D2(f)|^2``, and a power law
``S(f) = S0 (f/f0)^beta`` fitted to its logarithm: the slope by Theil-Sen (a median of
slopes: a lightly damped mode, a reversal's burst or a tone's harmonic in a few bins
does not move it) over the read band's first two octaves (a mode's misfit higher up,
a 3 kHz mode under a PRBS at 20 kHz, tilted a slope over the whole band to read the
noise 2.2 x), the level by the median over its first octave (where the rows' chains
weigh it), within :data:`BETA_RANGE`, in the frequency ``f`` or in the
sampled frequency ``phi(f) = fs/pi sin(pi f/fs)`` (:func:`sampled_frequency`: a power
law aliased by sampling, or a first-order low-pass noise made at the sample rate, bends
towards Nyquist as ``phi^beta``), whichever the read band's shape follows better
(:func:`_law`).  At decimation 3-4, the band read from 500-667 Hz up, a law in ``f``
read a proving-ground low-pass noise's ``-2`` as -1.4 to -1.6, and the noise carried
into the band through the position's Butterworth came out at 0.26-0.45 x the truth
(docs/studies/2026-11-28-coloured-nulls.md).  The spectrum is read on the first difference of
``e`` (a low-frequency misfit falls by ``f^2`` before the gate's edges could spread
it) with the samples near a direction-uncertain one or a sign change gated out
(:func:`gate`: a stuck arm's constraint force, a reversal's switch).  White noise is
``beta = 0``, pink ``-1``, a first-order low-pass above its corner ``-2``.  The power law is then carried through each chain the diagnosis
applies to the position (the rows' acceleration: Butterworth, second difference,
decimation filter; the velocity: Butterworth, derivative), whose gain falls to zero
at DC, so that the extrapolation into the band weighs mostly near the band's edge;
and the position's Butterworth (the bristle and Dahl lengths' floor), whose gain at DC
weighs a steep spectrum's lowest frequencies: every chain is integrated from the
lowest frequency the Welch estimate resolves, ``fs/nperseg`` (slower wander is not
counted; a low-pass noise flat below a corner under that is counted as ``f^beta``
down to it: 0.9-1.5 x its truth on the proving ground's low-pass nulls).

One Welch pass and one regression on the rows: linear in the samples.  Checked on
recordings of the independent proving generator with white, pink and low-pass noise,
broadband and narrowband inputs, open and closed loop
(``tests/test_diagnose_noise.py``): the floor through the rows within a factor 2 of
the floor the true noise sequence gives.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal, stats

from servo.frf.estimate import psd

#: the spectrum is read from the rows' band edge up to this fraction of the sample rate
F_HIGH = 0.45
#: the read band starts at most here (a fraction of the sample rate), for a small
#: decimation whose band reaches far up
F_LOW_MAX = 0.2
#: the power law's exponent is kept within these: a sensor's noise falls no steeper
#: than ``f^-2`` (a first-order low-pass above its corner, a random walk) nor rises
#: faster than ``f``.  Read steeper, the force balance's misfit, which rises towards
#: the read band's bottom (2-7 x the noise at 200-500 Hz on an open-loop PRBS at
#: decimation 10), has tilted it; carried two decades down into the position's
#: Butterworth, -2.4 for -2 put that in-band figure at 2.8-3.4 x the truth
BETA_RANGE = (-2.0, 1.0)
#: Welch segments: at least this many, of a power of two between these lengths
MIN_SEGMENTS = 16
NPERSEG_RANGE = (256, 4096)
#: fewer bins than this in the read band: the estimate is not made
MIN_BINS = 16
#: the gate around direction-uncertain samples: zero within GUARD Butterworth periods
#: (``fs/fc`` samples each: the filtered velocity that decides "uncertain" is smeared by
#: about that much), a raised cosine over TAPER samples more (:func:`gate`); under
#: MIN_KEPT of the power left: no estimate
GUARD = 2.0
TAPER = 16
MIN_KEPT = 0.05
#: :meth:`NoiseSpectrum.std_through` integrates on at least this many frequencies
GRID = 1 << 15

METHOD = ("the force balance at the full sample rate (J*x'' + B*x' + K*x + h0 + Fc*sgn(x') - u) above the rows' band, "
          "where the input's motion cancels and the sensor noise rises as f^4: its Welch spectrum over J^2 |D2(f)|^2, "
          "a power law S0*(f/f0)^beta (f or the sampled frequency) fitted by Theil-Sen and carried into the band "
          "through the rows' filters")


@dataclass(frozen=True)
class NoiseSpectrum:
    """A one-sided position-noise PSD ``S(f) = s0 * (f/f0)**beta`` (m^2/Hz), read over
    ``band_hz`` from ``bins`` Welch bins (module doc)."""

    s0: float
    f0: float
    beta: float
    band_hz: tuple
    bins: int
    method: str = METHOD
    #: Hz: the lowest frequency the spectrum resolves (the Welch segment's ``fs/nperseg``);
    #: a chain's std counts the noise above it only (:meth:`std_through`); 0: from DC
    f_min: float = 0.0
    #: Hz: the law is in the sampled frequency ``phi(f)`` at this rate
    #: (:func:`sampled_frequency`); 0: in ``f``
    sampled_at: float = 0.0

    def psd(self, f: np.ndarray) -> np.ndarray:
        """``S(f)`` (m^2/Hz) at ``f`` (Hz, > 0; 0 at DC)."""
        f = np.asarray(f, dtype=float)
        out = np.zeros_like(f)
        pos = f > 0
        if self.sampled_at > 0:
            fp = np.minimum(f[pos], self.sampled_at / 2)
            ratio = sampled_frequency(fp, self.sampled_at) / sampled_frequency(self.f0, self.sampled_at)
            out[pos] = self.s0 * ratio**self.beta
        else:
            out[pos] = self.s0 * (f[pos] / self.f0) ** self.beta
        return out

    def std_through(self, h: np.ndarray, fs: float) -> float:
        """Std of this noise through a filter of impulse response ``h`` (full rate, at
        ``fs`` Hz): ``sqrt(int S(f) |H(f)|^2 df)`` over ``f_min`` .. ``fs/2`` (a chain
        with gain at DC, the position's Butterworth, weighs a steep spectrum's lowest
        frequencies: the integral starts where the spectrum was resolved, not where
        ``h``'s length happens to put its first bin), on a grid of at least
        :data:`GRID` points and ``h``'s length."""
        m = max(h.size, GRID)
        f, H = signal.freqz(h, worN=m, fs=fs)  # the filter's response, 0 .. fs/2 (step fs/(2 m))
        df = fs / (2 * m)
        w = np.abs(H) ** 2 * self.psd(f) * df
        if self.f_min > 0:  # the bins below f_min left out, the one across it in part
            w *= np.clip((f + df / 2 - self.f_min) / df, 0.0, 1.0)
        return float(math.sqrt(max(np.sum(w), 0.0)))

    def white_equivalent(self, h: np.ndarray, fs: float) -> float:
        """The std (m) of a white noise that gives the same std through ``h`` (its
        one-sided PSD ``2*sigma^2/fs``): ``std_through / ||h||``."""
        return self.std_through(h, fs) / max(float(np.linalg.norm(h)), 1e-300)

    def as_dict(self) -> dict:
        return {"method": self.method, "psd_m2_per_hz_at_f0": self.s0, "f0_hz": self.f0, "beta": self.beta,
                "read_band_hz": list(self.band_hz), "bins": self.bins, "lowest_resolved_hz": self.f_min,
                "law_in": "sampled frequency" if self.sampled_at > 0 else "frequency"}  # fmt: skip


#: the method when the spectrum could not be read (the rows' first estimate is kept)
FALLBACK = ("what the Butterworth removes (the position above its cutoff, a robust std), taken as white: the force "
            "balance's spectrum above the rows' band could not be read")


def describe(spec: NoiseSpectrum | None, noise_x: float, noise_v: float) -> dict:
    """``report.json``'s ``rows.noise``: the method, the spectrum's parameters, and
    ``noise_x`` (m: the white noise whose std through the rows' acceleration chain is
    the same, what the verdict's floor uses) and ``noise_v`` (m/s, through the
    velocity chain)."""
    out = {"method": FALLBACK} if spec is None else spec.as_dict()
    out.update(white_equivalent_m=noise_x, velocity_noise_m_s=noise_v)
    return out


def describe_text(d: dict) -> str:
    """One line of the summary from :func:`describe`'s dict."""
    if "beta" not in d:
        return f"{d['white_equivalent_m']:.3g} m RMS, white, from {d['method']}"
    lo, hi = d["read_band_hz"]
    law = f"f^{d['beta']:.2g}"
    if d.get("law_in") == "sampled frequency":
        law = f"phi^{d['beta']:.2g} (phi = fs/pi sin(pi f/fs), the sampled frequency)"
    return (f"{d['white_equivalent_m']:.3g} m RMS white-equivalent through the rows' filters; spectrum "
            f"~ {law}, read at {lo:.4g}-{hi:.4g} Hz from the force balance at the full rate (the input's "
            "motion cancels there)")  # fmt: skip


def second_difference_gain(f: np.ndarray, fs: float) -> np.ndarray:
    """``|D2(f)|`` (1/s^2) of the three-point second difference at ``fs`` Hz."""
    return (2.0 - 2.0 * np.cos(2 * np.pi * np.asarray(f) / fs)) * fs * fs


def welch_nperseg(n: int) -> int:
    """Segment length for ``n`` samples: the largest power of two in
    :data:`NPERSEG_RANGE` leaving :data:`MIN_SEGMENTS` half-overlapping segments."""
    lo, hi = NPERSEG_RANGE
    nper = hi
    while nper > lo and (2 * n) // nper - 1 < MIN_SEGMENTS:
        nper //= 2
    return min(nper, n)


def gate(uncertain: np.ndarray, guard: int, taper: int = TAPER) -> np.ndarray:
    """(n,) weights in [0, 1]: 0 within ``guard`` samples of an ``uncertain`` one ((n,)
    bool), rising over ``taper`` samples as a raised cosine, 1 beyond."""
    n = uncertain.size
    idx = np.arange(n)
    if not uncertain.any():
        return np.ones(n)
    last = np.maximum.accumulate(np.where(uncertain, idx, -(10**9)))
    nxt = np.minimum.accumulate(np.where(uncertain, idx, 2 * 10**9)[::-1])[::-1]
    dist = np.minimum(idx - last, nxt - idx).astype(float)
    w = np.clip((dist - guard) / max(taper, 1), 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * w)


def estimate(e: np.ndarray, J: float, fs: float, f_edge: float, uncertain: np.ndarray | None = None,
             guard: int = 16) -> NoiseSpectrum | None:  # fmt: skip
    """The position-noise spectrum (module doc) from the full-rate force-balance
    residual ``e`` (n,) of a model with inertia ``J`` (F s^2/m) at ``fs`` Hz, read above
    the rows' band edge ``f_edge`` (Hz), with the samples near an ``uncertain`` one
    ((n,) bool: the direction of motion unknown, where a stuck arm's friction is a
    constraint force and the Coulomb column's switch is not placed) gated out
    (:func:`gate`, ``guard`` samples); None where the read band holds too few bins, the gate leaves too
    little, or the spectrum is not positive."""
    if not (J > 0 and np.isfinite(J)):
        return None
    n = e.size
    nper = welch_nperseg(n)
    if nper < 32:
        return None
    # first difference: the low-frequency misfit (which the rows test) falls by f^2
    # before the gate's edges could spread it; divided out below, exactly
    z = np.diff(e, prepend=e[0])
    if uncertain is not None:
        g = gate(uncertain, guard)
        kept = float(np.mean(g * g))
        if kept < MIN_KEPT:
            return None
        z = z * g / math.sqrt(kept)
    f, P = psd(z, fs, nper)
    lo = min(f_edge, F_LOW_MAX * fs)
    hi = F_HIGH * fs
    sel = (f >= lo) & (f <= hi) & (P > 0)
    if sel.sum() < MIN_BINS:
        return None
    fb = f[sel]
    S = P[sel] / (J * J * second_difference_gain(fb, fs) ** 2 * (2.0 - 2.0 * np.cos(2 * np.pi * fb / fs)))
    ly = np.log(S)
    # the slope over the read band's first two octaves, the level over its first
    # octave (where the rows' chains weigh it); in the frequency f or in the sampled
    # frequency phi(f) (a noise shaped before or after sampling: a first-order
    # low-pass's f^-2 is phi^-2, bending towards Nyquist), whichever the spectrum's
    # shape follows better (:func:`_law`)
    near = fb <= 4.0 * fb[0]
    if near.sum() < MIN_BINS:
        near = np.ones(fb.size, bool)
    first = fb <= 2.0 * fb[0]
    if first.sum() < MIN_BINS // 2:
        first = np.arange(fb.size) < MIN_BINS // 2
    f0 = float(math.sqrt(fb[first][0] * fb[first][-1]))
    fits = [_law(np.log(sampled_frequency(fb, fs) if smp else fb), ly, near, first,
                 math.log(float(sampled_frequency(np.array([f0]), fs)[0]) if smp else f0)) + (smp,)
            for smp in (False, True)]  # fmt: skip
    beta, c, _, sampled = min(fits, key=lambda t: t[2])
    # the level less the median's bias for a Welch estimate (log of a chi-square with
    # 2K dof, K the segments)
    K = max((2 * n) // nper - 1, 1)
    c -= math.log(stats.chi2.median(2 * K) / (2 * K))
    return NoiseSpectrum(float(math.exp(c)), f0, beta, (float(fb[0]), float(fb[-1])), int(fb.size), f_min=fs / nper,
                         sampled_at=fs if sampled else 0.0)  # fmt: skip


def sampled_frequency(f: np.ndarray, fs: float) -> np.ndarray:
    """``phi(f) = fs/pi * sin(pi f/fs)`` (Hz): ``f`` at low frequencies, ``fs/pi`` at
    Nyquist.  A noise that is ``f^beta`` before sampling at ``fs`` (aliased) or shaped
    by a first-order recursion after it is ``phi^beta`` (exactly for beta = -2:
    ``sum_k 1/(f + k fs)^2 = (pi/fs)^2 / sin^2(pi f/fs)``)."""
    return fs / math.pi * np.sin(np.pi * np.asarray(f, dtype=float) / fs)


#: groups of the read band whose mean log-spectrum judges a law's shape
SHAPE_GROUPS = 8


def _law(lx: np.ndarray, ly: np.ndarray, near: np.ndarray, first: np.ndarray, lx0: float) -> tuple:
    """``(beta, log level at lx0, misfit)`` of a power law in the variable ``exp(lx)``:
    the Theil-Sen slope over ``near`` (within :data:`BETA_RANGE`), the median level over
    ``first``, and the sum of squares of the mean residual about the slope as read in
    :data:`SHAPE_GROUPS` equal groups of ``near`` (a spectrum's curvature against the
    law; the Welch scatter averages out)."""
    lxn, lyn = lx[near], ly[near]
    raw = float(stats.theilslopes(lyn, lxn)[0]) if lxn.size <= 600 else _thinned_theil(lxn, lyn)
    # the shape judged on the slope as read, the law kept within BETA_RANGE
    r = lyn - raw * lxn
    groups = np.array_split(r - np.median(r), min(SHAPE_GROUPS, r.size))
    beta = float(np.clip(raw, *BETA_RANGE))
    c = float(np.median(ly[first] - beta * (lx[first] - lx0)))
    return beta, c, float(sum(g.mean() ** 2 for g in groups))



def _thinned_theil(lx: np.ndarray, ly: np.ndarray) -> float:
    """Theil-Sen slope on bins merged to at most 600 (log-averaged in groups): the
    pairwise medians cost ``N^2``."""
    g = int(math.ceil(lx.size / 600))
    m = (lx.size // g) * g
    return float(stats.theilslopes(ly[:m].reshape(-1, g).mean(1), lx[:m].reshape(-1, g).mean(1))[0])


__all__ = ["FALLBACK", "METHOD", "NoiseSpectrum", "describe", "describe_text", "estimate", "gate", "sampled_frequency",
           "second_difference_gain", "welch_nperseg"]

"""The frequency-domain path: the recording's own frequency response against the model's.

The force-balance rows are decimated (:mod:`servo.diagnose.band`): they cover ``0 ..
0.4*fs/q`` Hz, and a mode above that edge never shows in them.  This path works at the
full sample rate on the input-to-position frequency response instead, over the whole
band with excitation (the **FRF band**, from :data:`LOW_BINS` bins of the Welch grid to
``TOP*fs``, ``TOP`` = 0.49):

1. **Measured response.**  ``H1 = P_ux/P_uu`` over Welch segments (Hann, 50 % overlap)
   with the coherence ``g2``, by the project's one estimator (:mod:`servo.frf.estimate`,
   the segments it averages chosen here), separately on the training part (the samples up to the
   last training row) and on the test part (the rest), from the force the model's
   linear part sees (:func:`linear_input`: the friction's force, which a loop feeds
   back into the input, taken off) to the measured position, over the segments in
   which the arm slides (a stuck arm does not follow the input).  Both signals first
   go through the same zero-phase high-pass (Butterworth, order 4, at half the FRF
   band's lower edge): a filter common to ``u`` and ``x`` cancels in the ratio, and it
   keeps the position's large low-frequency motion from leaking through the window's
   side lobes.  Each complex component of ``H1`` has the estimator's standard deviation
   ``|H1|*sqrt((1 - g2)/(2*K_eq*g2))`` (Bendat & Piersol, *Random Data*, eq. 9.90;
   ``K_eq`` the equivalent independent averages of the overlapping segments used).
2. **The model's response** over the same bins: the rigid body ``1/(J s^2 + B s + K)``
   plus every mode of the model (``x_meas = x + gain*q``, ``q'' + 2*zeta*w*q' + w^2*q =
   u/J``, the :mod:`~servo.diagnose.terms` ``resonance`` term), each part discretised
   exactly for the recorded zero-order-hold input, and averaged over the Welch window's
   spectral kernel (what a Welch estimate of the same response would read, for a
   locally flat input spectrum).
3. **Departure test** (level fixed before any scoring): a bin of the FRF band is
   usable where the coherence is at least :data:`COH_MIN` and the input has power of
   its own there (:func:`excited`: not a slow drive's coherent leakage), whatever the
   model predicts (:func:`usable`).  In a loop ``H1`` is biased by the sensor noise the
   controller feeds back into the input (towards ``-1/C``); :func:`bias` bounds it per
   bin from the noise level (:func:`noise_level`, :func:`white_level`).  Per usable
   bin, the complex departure after a smooth factor ``c0 + c1*log f`` is taken off
   (:func:`detrended`), less the bias bound, over the random error, squared, is at
   most chi-square with 2 degrees of freedom under the model; a bin departs beyond the
   ``alpha/N_bins`` quantile (Bonferroni over the bins) *and* by at least
   :data:`REL_MARGIN` of the model's response; the response departs where two
   neighbouring bins do, and each run of departing bins is located (:func:`located`).
   Fewer than :data:`MIN_BINS` usable bins: the recording has no input power in the
   band, and the path says so and stops.
4. **Fit.**  Where the training part departs, a mode (``frequency_hz``, ``zeta``,
   ``gain``: the ``resonance`` term's parameters, so that ``final_model.toml`` and
   :func:`servo.diagnose.simulate.drive_params` carry it) is fitted to the measured
   response by weighted complex least squares (``scipy.optimize.least_squares``,
   started from a grid of damping values around the peak of the departure that weighs
   most, over the usable bins from a third below to half above it, the smooth factor
   solved linearly inside), with standard deviations from the Jacobian (inflated by the
   Hann window's noise bandwidth, 1.5 bins, for the correlation of neighbouring bins).
   A mode at the damping bound of the vocabulary is not a mode (the ``resonance``
   term's rule).  Up to :data:`MAX_MODES` modes, one at a time, while the training part
   still departs; a departure whose mode is dropped (here or in step 5) is not fitted
   again, and the next one is tried.
5. **Proof on the test part**: the held-out part's own ``H1`` against the model without
   and with the mode (the sum of squared departures over their variances on the test
   part's usable bins, the smooth factor refitted for each); a mode that does not lower
   it by more than the chi-square bound of its three parameters at ``alpha`` (the rule
   :func:`support` holds the rows' modes to), scaled by the misfit the model with it
   leaves per degree of freedom where that exceeds 1 (as :func:`input_path` does), is
   dropped (reported with its parameters).  Any three free parameters lower that sum a
   little on noise alone: a null driven by long seek strokes, whose input above 200 Hz
   is the loop's fed-back sensor noise, had two modes at 200-217 Hz kept for lowering
   it from 67.9 to 67.0 (bound 7.8); and where the model misses the response broadly
   (a closed-loop step recording with a 350 Hz mode, coloured noise: 179 510 over 484
   bins, 186 per degree of freedom) a mode at the damping bound at 85 Hz lowered it by
   0.6 %; dropped, it no longer stopped the path before the true mode (348 Hz).
6. **An instrument, where the recording has one.**  A recording's ``r`` column (a
   reference, or better the excitation injected at the plant's input: what a lab
   records for a closed-loop frequency response) is exogenous: the sensor noise a loop
   feeds back into ``u`` is uncorrelated with it.  Then ``H = P_rx/P_ru`` (the
   instrumental-variable estimate of :func:`servo.frf.estimate.instrumental`, here on
   the sliding segments and the high-passed signals of step 1) has no closed-loop
   bias, so the margin is :data:`REL_MARGIN` alone; its variance and usable bins are in
   :func:`measure`.  Where ``r`` has too little power in the band for
   :data:`MIN_BINS` usable bins in either part, the path falls back to ``H1`` and says
   so.  An open loop needs none.
7. **A mode the rows named** is held against the response (:func:`support`): kept
   where the response shows it, dropped where it contradicts it, and where the
   response cannot resolve it, kept only below the rows' band edge.
8. **A delay or a sensor lag the rows named** is held against the response
   (:func:`input_path`): each input-path term's factor comes from its own module's
   hook (``frf_factor``, ``frf_param``: :func:`path_terms`), and the held-out response
   chooses between them.

Cost: 0.4 s of a 1 000 000-sample diagnosis (two high-pass filters, the friction's
force at full rate, the spectra of both parts).  ``docs/verdict.md`` section 6b.
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, signal, stats

from servo.diagnose.band import band_hz
from servo.frf.estimate import WelchSettings, estimate, frequencies, segment_starts, spectra, window_kernel
from servo.diagnose.terms import VOCABULARY
from servo.physics import BASELINE_TERMS, diagnosed_by

#: the vocabulary's term this path names (a flexible mode: the effect whose
#: ``diagnosed_by`` is ``"frf"``), its response and its limits from its own module
MODE = diagnosed_by("frf")
MODE_TERM = VOCABULARY[MODE]

#: a bin is usable where the coherence is at least this (the variance formula is first
#: order; below ~0.5 the ratio of noisy spectra has heavier tails than it says)
COH_MIN = 0.5
#: a departure must be at least this share of the model's response, whatever the test
#: says (an inertia 1 % off, or the closed-loop bias above, is not a mode)
REL_MARGIN = 0.1
#: the closed-loop bias of H1 is ``|L/(1 + L)|/SNR`` of ``|H|`` (``L`` the loop gain,
#: unknown here): a departure counts only beyond ``BIAS_FACTOR/SNR`` (a sensitivity peak
#: of 2); on null recordings of the lead-lag loop the response read 5-9 % high where the
#: SNR was 10-17
BIAS_FACTOR = 2.0
#: where the input is all fed-back noise (a loop driven below the band, read far above
#: its crossover) ``H1`` reads ``-1/C`` and the second bound, ``sqrt(P_nn/P_uu)``, is
#: met with equality: it is taken this many times over, for a white noise level from
#: the rows' ``sigma_x`` that may be off by as much (a closed-loop multisine null's
#: response departed from the model by 80-380 x at 1.9-2.3 kHz with coherence 0.99,
#: 1.0-1.2 x that bound, its ``sigma_x`` 17 % below the generator's noise)
NOISE_FACTOR = 2.0
#: the white noise level is at most this quantile of the incoherent part over the
#: usable bins (:func:`white_level`)
NOISE_QUANTILE = 0.9
#: ... over the bins where the measured response is within this share of the model's
AGREE = 0.5
#: fewer usable bins than this in the FRF band: no input power above the rows' band
MIN_BINS = 8
#: a bin's input power must be at least this many times what the window's side lobes
#: can carry into it from bins at least :data:`LEAK_FROM` away (:func:`excited`)
LEAK_MARGIN = 10.0
LEAK_FROM = 3
#: the leakage of a slow drive's piece over a line's Hann side lobes, and its cap near
#: the main lobe (a line's own side lobe 3 bins away is 6e-4 of it) (:func:`leakage`)
LEAK_EXCESS = 1000.0
LEAK_CAP = 1e-3
#: bins of the running median that smooths the estimator's incoherent part into a noise
#: level (:func:`noise_level`)
NOISE_BINS = 9
#: a Welch segment is used when at most this share of its samples is where the arm may
#: stick (speed within its noise): a stuck arm does not follow the input, and segments
#: that hold one read a response too small by the share of time stuck (0.83 x the rigid
#: body on null seek strokes with dwells, before this rule)
STUCK_MAX = 0.02
#: modes this path adds at most (the ``resonance`` term's own limit counts the model's too)
MAX_MODES = 4
#: the test part gets at least this many Welch segments (the segment length follows)
MIN_SEGMENTS = 8
NPERSEG_MAX = 8192
NPERSEG_MIN = 64
#: the FRF band's upper edge, a share of the sample rate (the Nyquist frequency is 0.5)
TOP = 0.49
#: the FRF band's lower edge: at least this many bins of the Welch grid and this share
#: of the rows' band edge; the common high-pass sits at half of it (module doc, step 1).
#: Below an eighth of their edge the rows hold the force balance at many times the
#: frequency resolution, and a closed loop's H1 there reads the loop and the friction as
#: much as the plant (an outside suite's 20 kHz recording, rows' edge 800 Hz: 15-75 %
#: departures with coherence 0.99 at 39-49 Hz, on a model the rows had passed)
LOW_BINS = 4
LOW_SHARE = 0.125
#: the bounds of the damping of a mode (the ``resonance`` term's)
ZETA_BOUNDS = (0.001, MODE_TERM.ZETA_MAX)
#: equivalent noise bandwidth of the Hann window, bins: neighbouring bins are correlated
ENBW = 1.5
#: samples of the window's spectral kernel per bin, and its half-width in bins
KERNEL_RES, KERNEL_HALF = 4, 3


@dataclass
class Response:
    """One part's measured response: ``f`` (k,) Hz, ``H`` (k,) complex m/F, ``coh`` (k,),
    ``rel_std`` (k,) of each complex component relative to ``|H|``, ``Puu`` (k,)
    the (high-passed) input's spectrum the response is read from (with an instrument,
    the part of it the instrument explains), ``K``/``K_eq`` segments used, ``samples``,
    ``segments_all`` the segments before those where the arm may stick were left out,
    ``method`` ``"H1"`` or ``"instrumental"`` (:func:`measure`)."""

    f: np.ndarray
    H: np.ndarray
    coh: np.ndarray
    rel_std: np.ndarray
    Puu: np.ndarray
    K: int
    K_eq: float
    samples: int
    segments_all: int = 0
    method: str = "H1"
    #: (k,) the position's power per Hz the response does not explain (the estimator's
    #: incoherent part, ``P_xx*(1 - g2)`` for ``H1``): the sensor noise where the input is
    #: the excitation alone, less in a loop where the input carries fed-back noise
    Pnn: np.ndarray | None = None
    #: (k,) bins where the input has power of its own (:func:`excited`, computed once)
    own: np.ndarray | None = None


@dataclass
class Mode:
    """A mode fitted by this path: the ``resonance`` parameters, their std, the evidence
    (``train_departure``/``train_after``: the training part's departure tests without and
    with it, ``test_sse_before``/``_after``: the held-out sums of ``z2``) and, if it was
    dropped, why."""

    params: dict
    std: dict
    evidence: dict = field(default_factory=dict)
    reason: str = ""


@dataclass
class Result:
    """What the path did: ``band_hz`` the FRF band, ``note`` (why it stopped, if it
    did), the measured responses, the modes kept and dropped, the departure tests of
    the model before and after on the test part (``None`` when skipped)."""

    band_hz: list
    note: str = ""
    #: the rows' band edge (Hz): the rows resolve nothing above it
    rows_edge_hz: float = 0.0
    ran: bool = False
    #: ``"H1"``, or ``"instrumental"`` with the recording's ``r`` as instrument
    method: str = "H1"
    nperseg: int = 0
    train: Response | None = None
    test: Response | None = None
    modes: list = field(default_factory=list)
    dropped: list = field(default_factory=list)
    before: dict | None = None
    after: dict | None = None
    seconds: float = 0.0
    #: the model's response in the test part's bins without and with the modes kept, and
    #: the bins the tests used there (for the figure)
    model_before: np.ndarray | None = None
    model_after: np.ndarray | None = None
    usable_test: np.ndarray | None = None
    usable_train: np.ndarray | None = None
    #: the white sensor-noise level the bias bound starts from (one-sided, per Hz)
    noise_psd: float = 0.0

    def summary(self) -> dict:
        """JSON-ready description (``report.json``'s ``frf``)."""
        def part(r):
            return None if r is None else {"samples": r.samples, "segments": r.K, "segments_all": r.segments_all,
                                           "equivalent_averages": r.K_eq}

        return {"band_hz": self.band_hz, "ran": self.ran, "method": self.method, "note": self.note,
                "nperseg": self.nperseg,
                "resolution_hz": (float(self.train.f[1] - self.train.f[0]) if self.train is not None else None),
                "train": part(self.train), "test": part(self.test),
                "rows_edge_hz": self.rows_edge_hz, "white_noise_psd": self.noise_psd,
                "level": {"coherence_min": COH_MIN, "rel_margin": REL_MARGIN, "bias_factor": BIAS_FACTOR,
                          "noise_factor": NOISE_FACTOR, "leak_margin": LEAK_MARGIN},
                "test_departure_before": self.before, "test_departure_after": self.after,
                "modes": [{"params": m.params, "std": m.std, "evidence": m.evidence} for m in self.modes],
                "dropped": [{"params": m.params, "std": m.std, "evidence": m.evidence, "reason": m.reason}
                            for m in self.dropped]}  # fmt: skip


# ------------------------------------------------------------------ the measured response
def sliding_segments(moving: np.ndarray, nperseg: int) -> int:
    """Welch segments of ``nperseg`` (50 % overlap) in which the arm slides (at most
    :data:`STUCK_MAX` of the samples outside ``moving``)."""
    if moving.size < nperseg:
        return 0
    starts = np.arange(0, moving.size - nperseg + 1, nperseg // 2)
    c = np.concatenate([[0], np.cumsum(~moving)])
    return int(np.sum((c[starts + nperseg] - c[starts]) / nperseg <= STUCK_MAX))


def choose_nperseg(moving_train: np.ndarray, moving_test: np.ndarray, shortest: int) -> int:
    """The largest power of two from :data:`NPERSEG_MAX` down to ``shortest`` that gives
    the test part and the training part :data:`MIN_SEGMENTS` Welch segments in which the
    arm slides each; 0 if none does."""
    nper = NPERSEG_MAX
    while nper >= shortest:
        if sliding_segments(moving_test, nper) >= MIN_SEGMENTS and sliding_segments(moving_train, nper) >= MIN_SEGMENTS:
            return nper
        nper //= 2
    return 0


def measure(u: np.ndarray, x: np.ndarray, moving: np.ndarray, dt: float, nperseg: int, highpass_hz: float,
            z: np.ndarray | None = None) -> Response:
    """The response from ``u`` to ``x`` ((n,) each) by the project's one estimator
    (:func:`servo.frf.estimate.spectra` and :func:`~servo.frf.estimate.estimate`) over
    the Welch segments of ``nperseg`` samples (Hann, 50 % overlap, mean removed) in which
    the arm slides: at most :data:`STUCK_MAX` of their samples outside ``moving`` (n,)
    bool; after a common zero-phase high-pass at ``highpass_hz`` (module doc, step 1).

    Without ``z``: ``H1 = P_ux/P_uu``.  With an instrument ``z`` (n,) (the recording's
    ``r``: a reference or an excitation injected in the loop, uncorrelated with the
    sensor's noise): ``H = P_zx/P_zu``, which the noise a loop feeds back into ``u``
    does not bias (module doc, step 6).  Both with the estimator's one random-error
    formula, ``rel_std = sqrt(P_vv/(2*K_eq*g2_zu*P_uu*|H|^2))``, ``P_vv`` the spectrum of
    the part of the position the response does not explain (Bendat & Piersol eq. 9.90
    in open loop, ``g2_zu = 1``), ``K_eq`` counting only the pairs of segments used
    that overlap.  ``coh``: the estimator's coherence (the input's share of the
    position), with an instrument no more than the instrument's coherence with the
    input (the first-order formula needs the denominator ``P_zu`` well estimated);
    ``Puu`` the input's power the instrument explains, ``g2_zu*P_uu`` (``P_uu`` for
    ``H1``)."""
    fs = 1.0 / dt
    sos = signal.butter(4, highpass_hz / (fs / 2), btype="high", output="sos")
    sig = {"u": signal.sosfiltfilt(sos, u), "x": signal.sosfiltfilt(sos, x)}
    pairs = [("u", "x")]
    if z is not None:
        sig["z"] = signal.sosfiltfilt(sos, z)
        pairs += [("z", "u"), ("z", "x")]
    settings = WelchSettings(nperseg=nperseg, overlap=0.5, window="hann", detrend="constant")
    starts = segment_starts(u.size, nperseg, settings.noverlap)
    c = np.concatenate([[0], np.cumsum(~moving)])
    stuck = (c[starts + nperseg] - c[starts]) / nperseg
    sel = starts[stuck <= STUCK_MAX]
    method = "H1" if z is None else "instrumental"
    f = frequencies(nperseg, dt)
    if sel.size == 0:
        nf = f.size
        nan = np.full(nf, np.nan)
        return Response(f, nan.astype(complex), np.zeros(nf), np.full(nf, np.inf), np.zeros(nf), 0, 0.0, u.size,
                        method=method, Pnn=np.full(nf, np.inf))
    est = estimate(spectra(sig, dt, settings, pairs, sel), "u", "x", None if z is None else "z")
    # usable where the input's share of the output is, and (instrument) where the
    # instrument explains the input (the ratio's denominator): the smaller of the two
    coh = np.minimum(est.coherence, est.g2_ru)
    with np.errstate(divide="ignore", invalid="ignore"):
        Pnn = np.abs(est.H) ** 2 * est.g2_ru * est.Puu * (1.0 - est.coherence) / est.coherence
    return Response(est.f, est.H, np.nan_to_num(coh), np.nan_to_num(est.rel_std, nan=np.inf),
                    np.nan_to_num(est.g2_ru * est.Puu), est.K, float(est.K_eq), u.size, int(starts.size), method,
                    np.nan_to_num(Pnn, nan=np.inf, posinf=np.inf))


#: the terms whose force the response's linear part holds, ``J*s^2 + B*s + K`` and the
#: modes (every other column term's force is taken off the input first, :func:`linear_input`)
RIGID = {k: BASELINE_TERMS[k] for k in ("J", "B", "K")}
LINEAR = (*RIGID.values(), MODE)


def linear_input(design, fit, inputs=None) -> np.ndarray:
    """The force the linear part of ``fit`` sees (n,): the recorded input through the
    model's input terms (saturation, delay) less every other column term's force at full
    rate (friction, offset, hysteresis, cogging...).  In a loop the friction's force is
    fed back into the input, and ``H1`` from the recorded input reads it as a response
    (on null recordings up to 25 % and 10 degrees off near the band edge).  ``inputs``:
    the model whose input terms apply (default ``fit.model``; :func:`input_path` leaves
    the term it weighs out)."""
    u = design.u_eff(fit.model if inputs is None else inputs)
    d = np.zeros(u.size)
    for i, t in enumerate(fit.model.terms):
        phys = VOCABULARY[t.physics]
        if phys.path.kind != "column" or t.physics in LINEAR:
            continue
        d += design.full_columns(t, fit.model) @ np.asarray(fit.coefs[i], dtype=float)  # a sensor lag's too
    return u - d


# ------------------------------------------------------------------ the model's response
@functools.lru_cache(maxsize=16)
def _zoh_tf(num: tuple, den: tuple, dt: float) -> tuple:
    bd, ad, _ = signal.cont2discrete((list(num), list(den)), dt, method="zoh")
    return np.ravel(bd), np.asarray(ad)


def _zoh(num, den, dt: float, f: np.ndarray) -> np.ndarray:
    """Frequency response at ``f`` (Hz) of the continuous ``num/den`` driven through a
    zero-order hold and sampled every ``dt`` (exact, ``cont2discrete``)."""
    bd, ad = _zoh_tf(tuple(map(float, num)), tuple(map(float, den)), float(dt))
    z = np.exp(2j * np.pi * f * dt)
    with np.errstate(divide="ignore", invalid="ignore"):  # a double integrator's pole at DC
        return np.polyval(bd, z) / np.polyval(ad, z)


def kernel(nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """The Hann window's power kernel (:func:`servo.frf.estimate.window_kernel`)."""
    return window_kernel("hann", nperseg, KERNEL_RES, KERNEL_HALF)


@dataclass
class Plant:
    """The linear part of a model seen from the input to the measured position: ``J``,
    ``B``, ``K``, ``delay_s``, its modes ``[(hz, zeta, gain)]``.  :meth:`of` leaves the
    delay at 0: :func:`linear_input` applies the model's delay to the input."""

    J: float
    B: float
    K: float
    delay_s: float = 0.0
    modes: list = field(default_factory=list)

    @classmethod
    def of(cls, fit) -> "Plant":
        p = fit.combined()
        modes = []
        for i, t in enumerate(fit.model.terms):
            if t.physics == MODE:
                q = fit.term_params(i)
                modes.append((q["frequency_hz"], q["zeta"], q["gain"]))
        J, B, K = (p.get(term, {}).get(k, 0.0) for k, term in RIGID.items())
        return cls(J, B, K, 0.0, modes)


def rigid_response(pl: Plant, f: np.ndarray, dt: float) -> np.ndarray:
    return _zoh([1.0], [pl.J, pl.B, pl.K], dt, f) * np.exp(-2j * np.pi * f * pl.delay_s)


def mode_response(pl: Plant, hz: float, zeta: float, f: np.ndarray, dt: float) -> np.ndarray:
    """Response of one mode of unit gain (the mode term's hook,
    :meth:`servo.physics.resonance.Resonance.frf_mode`), delayed by ``pl.delay_s``."""
    return MODE_TERM.frf_mode(pl.J, hz, zeta, f, dt) * np.exp(-2j * np.pi * f * pl.delay_s)


def _smooth(fun, f: np.ndarray, df: float, ker) -> np.ndarray:
    off, wt = ker
    ff = (f[:, None] + off[None, :] * df).ravel()
    return (fun(ff).reshape(f.size, off.size) * wt[None, :]).sum(axis=1)


def model_response(pl: Plant, f: np.ndarray, dt: float, df: float, ker, factor=None) -> np.ndarray:
    """What a Welch ``H1`` of the model would read in the bins ``f`` (module doc, step 2);
    ``factor(ff)``: an input-path term's factor on the whole response (a delay's, a
    sensor lag's: :func:`input_path`)."""

    def fun(ff):
        h = rigid_response(pl, ff, dt)
        for hz, z, g in pl.modes:
            h = h + g * mode_response(pl, hz, z, ff, dt)
        return h if factor is None else h * factor(ff)

    return _smooth(fun, f, df, ker)


# ------------------------------------------------------------------ the departure test
def noise_level(resp: Response, noise_psd: float) -> np.ndarray:
    """Per bin, the sensor noise's power per Hz in the position (k,): the larger of the
    white level ``noise_psd`` (the rows' ``sigma_x``) and the estimator's incoherent part
    (``resp.Pnn``, a running median over :data:`NOISE_BINS` bins).  Coloured noise
    shows in the second where the first, white, is below it; an input partly made of
    fed-back noise lowers the second, never the first."""
    p = np.asarray(resp.Pnn if resp.Pnn is not None else np.zeros(resp.f.size), dtype=float)
    p = np.where(np.isfinite(p), p, 0.0)
    h = NOISE_BINS // 2
    padded = np.pad(p, h, mode="edge")
    med = np.median(np.lib.stride_tricks.sliding_window_view(padded, NOISE_BINS), axis=1)
    return np.maximum(med, noise_psd)


def white_level(noise_psd: float, resp: Response, use: np.ndarray, Hm: np.ndarray) -> float:
    """The white sensor-noise level the bias bound starts from: the rows' (``noise_psd``
    from ``sigma_x``), but at most the :data:`NOISE_QUANTILE` quantile of the training
    part's incoherent part (:func:`noise_level`'s running median) over its usable bins
    where the measured response agrees with the model's within :data:`AGREE` (at least
    :data:`MIN_BINS` of them).  There the input is the excitation and the incoherent
    part is the sensor noise; where a loop's input is fed-back noise ``H1`` reads
    ``-1/C``, far from the model, and the incoherent part falls below the noise (a
    seek loop's and a quantised loop's high bins: without that rule the level fell and
    they departed by 25-2000 x).  A ``sigma_x`` that read driven motion as noise (a
    broadband input drives the arm above the rows' filter: 100 x the true noise on an
    open-loop PRBS at 20 kHz) would otherwise hide every departure behind the bound."""
    if resp.Pnn is None:
        return noise_psd
    with np.errstate(divide="ignore", invalid="ignore"):
        agree = use & (np.abs(resp.H / Hm - 1.0) < AGREE)
    if agree.sum() < MIN_BINS:
        return noise_psd
    med = noise_level(resp, 0.0)[agree]
    med = med[np.isfinite(med)]
    if med.size < MIN_BINS:
        return noise_psd
    return float(min(noise_psd, np.quantile(med, NOISE_QUANTILE)))


def snr(resp: Response, Hm: np.ndarray, noise_psd: float) -> np.ndarray:
    """Per bin, the position power the model predicts from the measured input over the
    sensor noise's (:func:`noise_level`)."""
    return np.abs(Hm) ** 2 * resp.Puu / np.maximum(noise_level(resp, noise_psd), 1e-300)


def leakage(P: np.ndarray, need: np.ndarray | None = None) -> np.ndarray:
    """Per bin, the most that leakage can carry into it from the bins at least
    :data:`LEAK_FROM` away, ``max_d max(P[k-d], P[k+d])*W(d)`` (k,), with ``W(d)`` the
    Hann window's side-lobe envelope ``(pi*m*(m^2 - 1))^-2`` at ``m = d - 1/2`` (the
    worst offset of a line within its bin) times :data:`LEAK_EXCESS`, at most
    :data:`LEAK_CAP`: what a segment
    holds of a slow drive is not a line but its filtered, detrended piece, which leaks
    more (three slow sines leaked into the bins 4-10 away 15-60 x more than the
    envelope, with its slope).  A drive's leakage is coherent between the input and the
    position (the same piece in both): a bin that holds little else reads the response
    at the drive's frequency, not its own (the slow sines: 50 coherent bins at 20-230 Hz
    reading up to 1400 x the model's response).  A step's broadband content, real
    excitation, falls as ``1/f^2``, far slower than this.

    ``need`` (k,): stop once no bin's leakage can still reach its ``need`` (the caller
    compares with it; the result is then exact only where it matters, at or beyond
    ``need``, or where it was reached before the stop)."""
    P = np.nan_to_num(np.asarray(P, dtype=float))
    n = P.size
    out = np.zeros(n)
    top = float(P.max()) if n else 0.0
    for d in range(LEAK_FROM, n):
        m = d - 0.5
        w = min(LEAK_EXCESS / (math.pi * m * (m * m - 1.0)) ** 2, LEAK_CAP)
        out[d:] = np.maximum(out[d:], P[:-d] * w)
        out[:-d] = np.maximum(out[:-d], P[d:] * w)
        if need is not None and d % 16 == 0:
            open_ = out < need
            if not open_.any() or w * top < need[open_].min():
                break
    return out


def excited(resp: Response) -> np.ndarray:
    """Bins where the input drives the position with power of its own (k,): both the
    input's spectrum and the cross-spectrum ``|H|*P_uu`` at least :data:`LEAK_MARGIN`
    times what leakage from other bins can put there (:func:`leakage`).  A multisine's
    or a slow drive's bins between its lines are not; the cross-spectrum catches a
    loop's input whose own power there is fed-back noise while what it shares with
    the position is a tone's leakage (which carries the response at the tone, far
    larger than the bin's own below a mass's band)."""
    if resp.own is None:
        own = np.ones(resp.f.size, bool)
        for P in (np.nan_to_num(resp.Puu), np.nan_to_num(np.abs(resp.H) * resp.Puu, nan=0.0, posinf=0.0)):
            own &= P > LEAK_MARGIN * leakage(P, P / LEAK_MARGIN)
        resp.own = own
    return resp.own


def usable(resp: Response, Hm: np.ndarray, band: np.ndarray, noise_psd: float) -> np.ndarray:
    """Bins of ``band`` where the estimate is usable (module doc, step 3): the input has
    power of its own there (:func:`excited`) and the coherence is at least
    :data:`COH_MIN`, whatever the model predicts there (a mode the model lacks raises
    the measured response far above the model's: the bins that show it best are those
    where the model predicts least)."""
    return band & (resp.coh >= COH_MIN) & np.isfinite(resp.H) & excited(resp)


def bias(resp: Response, Hm: np.ndarray, noise_psd: float) -> np.ndarray:
    """Per bin, the bound of the closed-loop bias of ``H1`` relative to the model's
    response (module doc, step 3; 0 for an instrument's estimate, step 6): the bias is
    ``conj(d)*P_nn/P_uu`` (``d`` the loop's path from the sensor noise to the input),
    at most ``|T|/SNR`` of ``|H|`` (``T`` the complementary sensitivity, at most
    :data:`BIAS_FACTOR`) and at most ``sqrt(P_nn/P_uu)`` in absolute value (the fed-back
    noise is at most the whole input), ``1/sqrt(SNR)`` of the model's response, times
    :data:`NOISE_FACTOR`: the smaller of the two.  An open loop has no such bias; the
    recording does not say which it is."""
    if resp.method == "instrumental":
        return np.zeros(resp.f.size)
    s = np.maximum(snr(resp, Hm, noise_psd), 1e-300)
    return np.minimum(BIAS_FACTOR / s, NOISE_FACTOR / np.sqrt(s))


def margin(resp: Response, Hm: np.ndarray, noise_psd: float) -> np.ndarray:
    """Per bin, the relative departure below which nothing counts: at least
    :data:`REL_MARGIN`, and for ``H1`` at least the closed-loop bias bound
    (:func:`bias`)."""
    return np.maximum(REL_MARGIN, bias(resp, Hm, noise_psd))


def deviation(resp: Response, Hm: np.ndarray, noise_psd: float | None) -> np.ndarray:
    """Per bin, the uncertainty of the measured response against the model's (k,):
    the estimator's random error ``|H|*rel_std`` plus the closed-loop bias bound
    ``bias*|Hm|`` (:func:`bias`; ``noise_psd`` None: the random error alone).  Added,
    not in quadrature: the bias is systematic and does not average out.  The weights of
    the smooth factor and of the fit (a bin the loop's noise may bias counts less);
    the test itself reads the departure beyond the bias over the random error
    (:func:`departure`)."""
    sd = np.abs(resp.H) * resp.rel_std
    if noise_psd is None:
        return sd
    return sd + bias(resp, Hm, noise_psd) * np.abs(Hm)


def _columns(H: np.ndarray) -> list:
    """Real least-squares columns of a complex coefficient ``c`` times ``H``: ``c.real``
    and ``c.imag`` each give ``[Re; Im]`` of the product."""
    return [np.concatenate([H.real, H.imag]), np.concatenate([-H.imag, H.real])]


def detrended(resp: Response, Hm: np.ndarray, use: np.ndarray,
              noise_psd: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The measured response less the model's times the smooth factor ``c0 + c1*log f``
    (complex ``c``, weighted least squares over ``use``): residual (k,) complex, zero
    outside ``use``, and its standard deviations (k,).  The factor takes a level or a
    slowly turning phase off the comparison (an inertia a percent off, the closed loop's
    bias of ``H1`` where the input is partly fed-back noise, which turns ``H1``
    smoothly towards ``-1/C``); a mode's peak is narrow and stays.  The weights and the
    standard deviations are :func:`deviation`'s (with ``noise_psd``, the bias bound
    counts)."""
    sd = deviation(resp, Hm, noise_psd)
    e = np.zeros(resp.f.size, complex)
    idx = np.flatnonzero(use)
    if idx.size == 0:
        return e, sd
    L = np.log(resp.f[idx] / np.exp(np.mean(np.log(resp.f[idx]))))
    w = 1.0 / np.maximum(sd[idx], 1e-300)
    h = Hm[idx] * w
    A = np.column_stack(_columns(h) + _columns(h * L))
    y = np.concatenate([(resp.H[idx] * w).real, (resp.H[idx] * w).imag])
    c, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ c
    k = idx.size
    e[idx] = (r[:k] + 1j * r[k:]) / w
    return e, sd


def departure(resp: Response, Hm: np.ndarray, use: np.ndarray, alpha: float, noise_psd: float) -> dict:
    """The departure test of the model's response ``Hm`` on the usable bins ``use``
    (module doc, step 3): per bin ``z2`` (at most chi-square, 2 dof) of the detrended
    departure (:func:`detrended`) beyond the closed-loop bias bound (:func:`bias`;
    ``noise_psd`` None: no bias, a loop known open) over the estimator's random error;
    a bin departs beyond the Bonferroni bound and the margin; the
    response departs where two neighbouring bins do (the Hann window spreads any
    feature, however narrow, over its main lobe of 4 bins: a departure in one bin alone
    is the heavy tail of a ratio of noisy spectra); ``sse`` the sum of ``z2``."""
    n = int(use.sum())
    if n == 0:
        return {"bins": 0, "bound": None, "departs": False, "sse": 0.0, "flagged_hz": [], "worst_hz": None}
    e, _ = detrended(resp, Hm, use, noise_psd)
    sd = deviation(resp, Hm, None)  # the random error alone
    b = bias(resp, Hm, noise_psd) * np.abs(Hm) if noise_psd is not None else np.zeros(resp.f.size)
    excess = np.maximum(np.abs(e) - b, 0.0)  # what the closed-loop bias bound cannot account for
    z2 = np.where(use, excess**2 / np.maximum(sd, 1e-300) ** 2, 0.0)
    rel = np.where(use, np.abs(e) / np.maximum(np.abs(Hm), 1e-300), 0.0)
    bound = float(stats.chi2.isf(alpha / n, 2))
    hot = use & (z2 > bound) & (rel > REL_MARGIN)
    pair = hot[1:] & hot[:-1]
    flag = np.zeros_like(hot)
    flag[1:] |= pair
    flag[:-1] |= pair
    cand = flag if flag.any() else use
    deps = located(resp, flag, rel, z2)
    if deps:  # the departure that weighs most (its sum of z2); its peak, where it departs most
        top = max(deps, key=lambda d: d["sse"])
        cand = cand & (resp.f >= top["band_hz"][0]) & (resp.f <= top["band_hz"][1])
    worst = int(np.argmax(np.where(cand, rel, -1.0)))  # a mode's peak departs most (its antiresonance may test larger)
    return {"bins": n, "bound": bound, "departs": bool(flag.any()), "sse": float(z2[use].sum()),
            "flagged_hz": [float(v) for v in resp.f[flag]], "worst_hz": float(resp.f[worst]),
            "worst_z2": float(z2[worst]), "worst_rel": float(rel[worst]),
            "departures": deps, "flag": flag, "z2": z2}  # fmt: skip


def located(resp: Response, flag: np.ndarray, rel: np.ndarray, z2: np.ndarray) -> list:
    """Each coherent departure of a test (:func:`departure`): the runs of flagged bins
    (gaps of up to 3 bins, within the Hann main lobe, join two), each ``{band_hz: [lo, hi], peak_hz, size, coherence,
    bins}``, ``size`` the largest departure relative to the model's response there,
    ``coherence`` the lowest coherence in the run."""
    idx = np.flatnonzero(flag)
    out = []
    if idx.size == 0:
        return out
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 4) + 1)  # a main lobe of 4 bins
    for r in runs:
        k = r[np.argmax(rel[r])]
        out.append({"band_hz": [float(resp.f[r[0]]), float(resp.f[r[-1]])], "peak_hz": float(resp.f[k]),
                    "size": float(rel[k]), "coherence": float(np.min(resp.coh[r])), "bins": int(r.size),
                    "sse": float(z2[r].sum())})
    return out


def public(dep: dict | None) -> dict | None:
    """``dep`` without its per-bin arrays (for the report)."""
    if dep is None:
        return None
    out = {k: v for k, v in dep.items() if k not in ("flag", "z2")}
    fl = out.get("flagged_hz") or []
    out["flagged_hz"] = [fl[0], fl[-1]] if fl else []
    out["flagged_bins"] = len(fl)
    return out


# ------------------------------------------------------------------ the fit
def fit_mode(resp: Response, pl: Plant, use: np.ndarray, dep: dict, dt: float, df: float, ker, band_lo: float,
             f_top: float, noise_psd: float | None = None):  # fmt: skip
    """A mode fitted to the departure at its worst bin ``f0`` (module doc, step 4):
    ``(hz, zeta, gain, std, chi2)`` or None.  The model ``(Hm + gain*M(hz, zeta))*(c0 +
    c1*log f)`` over the usable bins from ``f0/1.5`` to ``1.5*f0`` (where the mode may
    lie), the smooth factor solved linearly inside (as in
    :func:`detrended`), ``hz``, ``zeta`` and ``gain`` by ``least_squares`` from the best
    of a grid around the worst bin."""
    Hm = model_response(pl, resp.f, dt, df, ker)
    f0 = dep["worst_hz"]
    lo_f, hi_f = max(band_lo, f0 / 1.5), min(f_top, f0 * 1.5)
    # fitted where it may lie: a larger departure elsewhere (another mode the model lacks)
    # would pull a mode fitted over the whole band away from this one
    idx = np.flatnonzero(use & (resp.f >= lo_f) & (resp.f <= hi_f))
    if idx.size < 4:
        return None
    f = resp.f[idx]
    L = np.log(f / np.exp(np.mean(np.log(f))))
    w = 1.0 / np.maximum(deviation(resp, Hm, noise_psd)[idx], 1e-300)
    y = np.concatenate([(resp.H[idx] * w).real, (resp.H[idx] * w).imag])
    hm = Hm[idx] * w

    def unit(hz, z):
        return _smooth(lambda ff: mode_response(pl, hz, z, ff, dt), f, df, ker) * w

    def resid(p):
        hz, lz, g = p
        h = hm + g * unit(hz, math.exp(lz))
        A = np.column_stack(_columns(h) + _columns(h * L))
        c, *_ = np.linalg.lstsq(A, y, rcond=None)
        return y - A @ c

    best = None
    A0 = np.column_stack(_columns(hm) + _columns(hm * L))
    for z in (0.005, 0.01, 0.02, 0.04, 0.08):
        for hz in f0 * np.array([0.97, 0.99, 1.0, 1.01, 1.03]):
            m = unit(hz, z)
            A = np.column_stack([A0, np.concatenate([m.real, m.imag])])
            c, *_ = np.linalg.lstsq(A, y, rcond=None)
            cost = float(np.sum((y - A @ c) ** 2))
            if best is None or cost < best[0]:
                best = (cost, hz, z, float(c[-1]))
    _, hz0, z0, g0 = best
    lo = [lo_f, math.log(ZETA_BOUNDS[0]), -np.inf]
    hi = [hi_f, math.log(ZETA_BOUNDS[1]), np.inf]
    x0 = [min(max(hz0, lo[0] + 1e-9 * df), hi[0] - 1e-9 * df), min(max(math.log(z0), lo[1] + 1e-9), hi[1] - 1e-9), g0]
    sol = optimize.least_squares(resid, x0, bounds=(lo, hi), x_scale=[df, 0.1, abs(g0) or 1.0], max_nfev=80)
    hz, lz, g = sol.x
    z = math.exp(lz)
    chi2 = float(np.sum(sol.fun**2))
    dof = max(sol.fun.size - 7, 1)
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * ENBW * max(chi2 / dof, 1.0)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        std = {"frequency_hz": float(sd[0]), "zeta": float(z * sd[1]), "gain": float(sd[2])}
    except np.linalg.LinAlgError:
        std = {}
    return float(hz), float(z), float(g), std, chi2


# ------------------------------------------------------------------ the path
def plant_with(pl: Plant, modes) -> Plant:
    return Plant(pl.J, pl.B, pl.K, pl.delay_s, list(pl.modes) + [(m.params["frequency_hz"], m.params["zeta"],
                                                                   m.params["gain"]) for m in modes])  # fmt: skip


def run(design, fit, alpha: float, instrument: np.ndarray | None = None, fit_modes: bool = True) -> Result:
    """The path on ``design``'s recording against the fitted model ``fit`` (module doc):
    the modes it proposes, each judged on the test part's own response (the caller adds
    the output check and the model's refit).  ``instrument`` (n,): the recording's ``r``,
    if it has one (step 6); used where both parts have :data:`MIN_BINS` usable bins with
    it, ``H1`` otherwise (``Result.method`` and ``note`` say which).  ``fit_modes``
    False: the measured responses and the model's departure only (:func:`support`)."""
    t0 = time.perf_counter()
    sig = design.sig
    fs = 1.0 / sig.dt
    edge = band_hz(sig.settings, fs)
    top = TOP * fs
    res = Result(band_hz=[float(edge), float(top)])
    pl = Plant.of(fit)
    if not pl.J > 0:
        res.note = "the model has no positive inertia J: no response to compare above the rows' band"
        return res
    n_train = int(design.train_samples.sum())
    moving = np.abs(sig.vf) > sig.v_threshold
    shortest = max(NPERSEG_MIN, 1 << int(math.ceil(math.log2(4.0 * fs / edge))))  # 4 bins over the rows' band
    nper = choose_nperseg(moving[:n_train], moving[n_train:], shortest)
    if nper == 0:
        res.note = (f"too few Welch segments of at least {shortest} samples in which the arm slides (speed above its "
                    f"noise): fewer than {MIN_SEGMENTS} in the test part or the training part")  # fmt: skip
        return res
    res.nperseg = nper
    f = frequencies(nper, sig.dt)
    df = float(f[1] - f[0])
    low = max(LOW_BINS * df, LOW_SHARE * edge)
    res.band_hz = [float(low), float(top)]
    res.rows_edge_hz = float(edge)
    hp = 0.5 * low
    u = linear_input(design, fit)
    ker = kernel(nper)
    band = (f >= low) & (f <= top)
    noise_psd = 2.0 * sig.noise_x**2 * sig.dt  # one-sided, white
    Hm_tr = model_response(pl, f, sig.dt, df, ker)
    Hm_te = Hm_tr

    def parts(z):
        zt, ze = (None, None) if z is None else (z[:n_train], z[n_train:])
        tr = measure(u[:n_train], sig.x[:n_train], moving[:n_train], sig.dt, nper, hp, zt)
        te = measure(u[n_train:], sig.x[n_train:], moving[n_train:], sig.dt, nper, hp, ze)
        return tr, te, usable(tr, Hm_tr, band, noise_psd), usable(te, Hm_te, band, noise_psd)

    if instrument is not None:
        tr, te, use_tr, use_te = parts(np.asarray(instrument, dtype=float))
        if min(use_tr.sum(), use_te.sum()) < MIN_BINS:
            res.note = (f"the recording's r has no power in the band ({int(use_tr.sum())} training and "
                        f"{int(use_te.sum())} test bins usable with it as instrument): H1 from the input instead")
            instrument = None
    if instrument is None:
        tr, te, use_tr, use_te = parts(None)
    noise_psd = white_level(noise_psd, tr, use_tr, Hm_tr)
    res.train, res.test, res.method = tr, te, tr.method
    res.before = public(departure(te, Hm_te, use_te, alpha, noise_psd))
    if use_tr.sum() < MIN_BINS or use_te.sum() < MIN_BINS:
        res.note = ((res.note + "; ") if res.note else "") + (f"the input has no power in the band of the frequency response: {int(use_tr.sum())} training "
                    f"and {int(use_te.sum())} test bins of {low:.4g}-{top:.4g} Hz are usable (coherence >= {COH_MIN:g}, "
                    f"fewer than {MIN_BINS})")  # fmt: skip
        res.after = res.before
        res.seconds = time.perf_counter() - t0
        return res
    res.ran = True
    res.noise_psd, res.usable_train = noise_psd, use_tr
    res.model_before, res.usable_test = Hm_te, use_te
    kept: list = []
    proof = float(stats.chi2.isf(alpha, 3))  # a mode's three parameters must earn their place (step 5)
    tried: list = []  # the departures (band, Hz) a mode was fitted to
    for _ in range(MAX_MODES if fit_modes else 0):
        if len(pl.modes) + len(kept) >= MODE_TERM.MAX_MODES:
            break
        cur = plant_with(pl, kept)
        Hm = model_response(cur, tr.f, sig.dt, df, ker)
        dep = departure(tr, Hm, use_tr, alpha, noise_psd)
        if not dep["departs"]:
            break
        got = None
        for d in sorted(dep["departures"], key=lambda d: -d["sse"]):  # the first that a mode fits
            if any(a <= d["peak_hz"] <= b for a, b in tried):  # a mode there was dropped: the next one
                continue
            got = fit_mode(tr, cur, use_tr, {**dep, "worst_hz": d["peak_hz"]}, sig.dt, df, ker, low, top, noise_psd)
            if got is not None:
                tried.append((d["band_hz"][0] - 2 * df, d["band_hz"][1] + 2 * df))
                break
        if got is None:
            break
        hz, z, g, std, chi2 = got
        m = Mode({"gain": g, "frequency_hz": hz, "zeta": z}, std)
        Hte0 = model_response(cur, te.f, sig.dt, df, ker)
        Hte1 = model_response(plant_with(cur, [m]), te.f, sig.dt, df, ker)
        d0, d1 = departure(te, Hte0, use_te, alpha, noise_psd), departure(te, Hte1, use_te, alpha, noise_psd)
        Htr1 = model_response(plant_with(cur, [m]), tr.f, sig.dt, df, ker)
        m.evidence = {"test": "H1 departure (chi-square 2 dof per bin, Bonferroni) + held-out H1 fit",
                      "train_departure": public(dep), "train_after": public(departure(tr, Htr1, use_tr, alpha, noise_psd)),
                      "test_sse_before": d0["sse"], "test_sse_after": d1["sse"], "test_bins": d0["bins"],
                      "test_bound": proof, "fit_chi2": chi2}  # fmt: skip
        why = MODE_TERM.judging.implausible(m.params)  # at the damping bound: not a lightly damped mode
        if why:
            m.reason = f"not a mode: {why}"
            res.dropped.append(m)
            continue
        # the misfit the model with the mode leaves, per degree of freedom (two per usable
        # bin, less the smooth factor's four and the mode's three), where it exceeds 1: a
        # response the model does not describe scales any parameter's gain up with it
        scale = max(d1["sse"] / max(2 * d1["bins"] - 7, 1), 1.0)
        m.evidence["test_scale"] = scale
        if not (d0["sse"] - d1["sse"]) / scale > proof:
            m.reason = (f"not confirmed: the held-out part's H1 departure fell from {d0['sse']:.4g} to "
                        f"{d1['sse']:.4g} with it, by no more than the chi-square bound of its three "
                        f"parameters ({proof:.3g}) times the misfit left per degree of freedom "
                        f"({scale:.3g})")  # fmt: skip
            res.dropped.append(m)
            continue  # the next departure may still be a mode
        kept.append(m)
    res.modes = kept
    res.model_before, res.usable_test = Hm_te, use_te
    res.model_after = model_response(plant_with(pl, kept), te.f, sig.dt, df, ker)
    res.after = public(departure(te, res.model_after, use_te, alpha, noise_psd))
    res.seconds = time.perf_counter() - t0
    return res


# ------------------------------------------------------------------ the input path
def path_terms() -> list:
    """The vocabulary's input-path terms the frequency response can weigh: those with the
    signal path's ``frf_factor(theta, f, dt)`` (their factor on the input-to-position response,
    (k,) complex at ``f`` Hz) and ``frf_param`` (the one parameter fitted to it): the
    delay (:mod:`servo.physics.time_delay`) and the sensor lag
    (:mod:`servo.diagnose.sensor_lag`)."""
    return [p for p in VOCABULARY.values() if p.path.frf_factor is not None and p.path.frf_param]


def _weighed(resp: Response, Hm: np.ndarray, use: np.ndarray, noise_psd: float) -> float:
    """The sum over ``use`` of ``|H - g*Hm|^2`` over :func:`deviation`'s variance, ``g``
    the real gain that minimises it (an inertia a little off is not the question)."""
    idx = np.flatnonzero(use)
    sd = deviation(resp, Hm, noise_psd)[idx]
    w2 = 1.0 / np.maximum(sd, 1e-300) ** 2
    h, m = resp.H[idx], Hm[idx]
    g = float(np.sum(w2 * (np.conj(m) * h).real) / max(np.sum(w2 * np.abs(m) ** 2), 1e-300))
    return float(np.sum(w2 * np.abs(h - g * m) ** 2))


#: the grid the one parameter of an input-path term is fitted over before refining (points)
PATH_GRID = 48
#: a term whose fitted parameter lies within this share of its range from a bound does
#: not stand in another's place (a closed-loop multisine's half-sample delay, pink
#: noise, neither term describing its response: the lag at its shortest lowered the
#: held-out sum by 0.7 % and took the delay's place)
PATH_EDGE = 0.01


def input_path(design, fit, alpha: float, instrument: np.ndarray | None = None) -> dict | None:
    """Which input-path term the recording's own frequency response prefers, where the
    rows named one (a delay or a sensor lag, :func:`path_terms`): ``None`` where they
    agree or the response cannot tell, else ``{"named", "physics", "theta", "evidence"}``
    for the term that should stand in its place.

    The rows tell a lag from a delay only by second-order terms in ``w*tau`` below their
    band edge (``docs/diagnosis.md``, section 3); the response over the whole excited
    band tells them by their shapes: a delay has a flat magnitude and a linear phase, a
    first-order lag a magnitude that rolls off and a phase that saturates.  The response
    is measured from the input *without* the named term (:func:`linear_input`) to the
    position, on the training and the test part as in :func:`run` (steps 1 and 6), with
    the recording's ``r`` as instrument where it has power in the band and otherwise the
    recorded input itself (through the other input terms): the friction's force taken
    off the input follows the motion, and where the input has no power of its own (an
    open-loop chirp's test part, swept past the band) its harmonics alone are coherent
    with the position (with ``H1`` they read as a response no input term shapes, and the
    fitted delay came out negative); fewer than :data:`MIN_BINS` usable bins in either
    part: the response cannot tell, and the rows' name stands.  Each
    term's parameter is fitted to the training part's response (model: the fit's rigid
    body and modes times the term's factor, times a real gain), over a log grid of
    :data:`PATH_GRID` points in the term's bounds refined by ``minimize_scalar``; the
    weighted sums of squares (:func:`deviation`'s variances, the closed-loop bias bound
    counted) are compared on the test part.  Another term replaces the named one where
    it lowers the held-out sum by more than the chi-square bound of one degree of freedom
    at ``alpha``, scaled by the misfit it leaves per degree of freedom where that
    exceeds 1 (a response neither term describes), lowers the training part's too, and
    its parameter is not at a bound of its range (:data:`PATH_EDGE`)."""
    names = {p.name: p for p in path_terms()}
    held = [t for t in fit.model.terms if t.physics in names]
    if len(held) != 1 or len(names) < 2:
        return None
    named = held[0]
    inputs = fit.model.without(named.physics)
    sig = design.sig
    fs = 1.0 / sig.dt
    edge = band_hz(sig.settings, fs)
    pl = Plant.of(fit)
    if not pl.J > 0:
        return None
    n_train = int(design.train_samples.sum())
    moving = np.abs(sig.vf) > sig.v_threshold
    shortest = max(NPERSEG_MIN, 1 << int(math.ceil(math.log2(4.0 * fs / edge))))
    nper = choose_nperseg(moving[:n_train], moving[n_train:], shortest)
    if nper == 0:
        return None
    f = frequencies(nper, sig.dt)
    df = float(f[1] - f[0])
    low = max(LOW_BINS * df, LOW_SHARE * edge)
    band = (f >= low) & (f <= TOP * fs)
    u = linear_input(design, fit, inputs)
    ker = kernel(nper)
    noise_psd = 2.0 * sig.noise_x**2 * sig.dt
    Hm = model_response(pl, f, sig.dt, df, ker)

    def parts(z):
        zt, ze = (None, None) if z is None else (z[:n_train], z[n_train:])
        tr = measure(u[:n_train], sig.x[:n_train], moving[:n_train], sig.dt, nper, 0.5 * low, zt)
        te = measure(u[n_train:], sig.x[n_train:], moving[n_train:], sig.dt, nper, 0.5 * low, ze)
        return tr, te, usable(tr, Hm, band, noise_psd), usable(te, Hm, band, noise_psd)

    # the instrument: the recording's r if it has power in the band, else the recorded
    # input itself (through the other input terms): the friction's force taken off ``u``
    # follows the motion, and where the input has no power of its own (a chirp's test
    # part, swept past a band) its harmonics alone are coherent with the position and
    # read as a response that no input term shapes
    tr = None
    for z in ([] if instrument is None else [np.asarray(instrument, dtype=float)]) + [design.u_eff(inputs)]:
        tr, te, use_tr, use_te = parts(z)
        if min(use_tr.sum(), use_te.sum()) >= MIN_BINS:
            break
    if use_tr.sum() < MIN_BINS or use_te.sum() < MIN_BINS:
        return None
    noise_psd = white_level(noise_psd, tr, use_tr, Hm)

    def response(phys, value):
        theta = {phys.path.frf_param: value}
        return model_response(pl, f, sig.dt, df, ker, lambda ff: phys.path.frf_factor(theta, ff, sig.dt))

    fitted = {}
    for name, phys in names.items():
        lo, hi, logs = phys.bounds(design, inputs)[phys.path.frf_param]
        if not hi > lo:
            continue
        grid = np.geomspace(lo, hi, PATH_GRID) if logs else np.linspace(lo, hi, PATH_GRID)
        costs = [_weighed(tr, response(phys, v), use_tr, noise_psd) for v in grid]
        k = int(np.argmin(costs))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        best, cost = float(grid[k]), float(costs[k])
        if b > a:
            if logs:
                sol = optimize.minimize_scalar(lambda z: _weighed(tr, response(phys, math.exp(z)), use_tr, noise_psd),
                                               bounds=(math.log(a), math.log(b)), method="bounded",
                                               options={"xatol": 1e-3})  # fmt: skip
                v = math.exp(sol.x)
            else:
                sol = optimize.minimize_scalar(lambda z: _weighed(tr, response(phys, z), use_tr, noise_psd),
                                               bounds=(a, b), method="bounded", options={"xatol": 1e-3 * (b - a)})
                v = float(sol.x)
            if sol.fun < cost:
                best, cost = v, float(sol.fun)
        fitted[name] = {"value": best, "train_sse": cost,
                        "test_sse": _weighed(te, response(phys, best), use_te, noise_psd),
                        "at_bound": bool(min(abs(best - lo), abs(hi - best)) <= PATH_EDGE * (hi - lo))}  # fmt: skip
    if named.physics not in fitted:
        return None
    own = fitted[named.physics]
    bound = float(stats.chi2.isf(alpha, 1))
    others = [(v["test_sse"], k) for k, v in fitted.items() if k != named.physics]
    if not others:
        return None
    sse, other = min(others)
    alt = fitted[other]
    evidence = {"test": "held-out frequency response, each input-path term fitted to the training part's (weighted sum "
                        "of squares, chi-square bound of one degree of freedom)",
                "named": named.physics, "bound": bound, "band_hz": [float(low), float(TOP * fs)],
                "bins": [int(use_tr.sum()), int(use_te.sum())], "method": tr.method,
                "terms": {k: {names[k].path.frf_param: v["value"], "train_sse": v["train_sse"], "test_sse": v["test_sse"]}
                          for k, v in fitted.items()}}  # fmt: skip
    # the misfit both leave, per degree of freedom (two per bin, less the gain and the
    # parameter): a response neither term describes scales the difference up with it
    scale = max(sse / max(2 * int(use_te.sum()) - 2, 1), 1.0)
    evidence["scale"] = scale
    if alt["at_bound"] or not ((own["test_sse"] - sse) / scale > bound and alt["train_sse"] < own["train_sse"]):
        return None
    evidence["reason"] = (f"the frequency response over {low:.4g}-{TOP * fs:.4g} Hz is a {other} rather than a "
                          f"{named.physics}: held-out departure {sse:.4g} against {own['test_sse']:.4g} "
                          f"(it must fall by more than {bound:.3g})")  # fmt: skip
    return {"named": named.physics, "physics": other, "theta": {names[other].path.frf_param: alt["value"]},
            "evidence": evidence}


def support(design, fit, alpha: float, instrument: np.ndarray | None = None) -> list:
    """Whether the recording's own frequency response supports each mode of ``fit``
    (the ``resonance`` terms the rows named): per mode ``(term_index, kept, evidence)``.

    * **shown**: the held-out part's departure (the sum of ``z2`` over the usable bins,
      :func:`departure`) falls with the mode by more than the chi-square bound of its
      three parameters at ``alpha``: kept;
    * **contradicted**: the mode would stand out of the response in a usable bin within
      2 bins of its frequency (its own response beyond the bias bound by the departure
      test's bound) and the response does not show it: dropped;
    * neither (the response cannot resolve it there): kept where the rows resolve it
      (below their band edge), dropped above it, where the rows alone cannot tell a
      mode from a delay or a filter.

    Every mode gets the second and third rule's verdict when the path cannot compare
    (``run``'s note says why).  Empty when ``fit`` has no mode."""
    idx = [i for i, t in enumerate(fit.model.terms) if t.physics == MODE]
    if not idx:
        return []
    sig = design.sig
    edge = band_hz(sig.settings, 1.0 / sig.dt)
    full = Plant.of(fit)
    res = run(design, fit, alpha, instrument, fit_modes=False)
    out = []
    if not res.ran:
        for j, i in enumerate(idx):
            hz = full.modes[j][0]
            ev = {"rule": "not resolved", "band_hz": res.band_hz, "rows_edge_hz": float(edge)}
            if hz >= edge:
                ev["reason"] = (f"neither the rows (band edge {edge:.4g} Hz) nor the frequency response ({res.note}) "
                                f"resolve a mode at {hz:.4g} Hz")  # fmt: skip
            out.append((i, hz < edge, ev))
        return out
    te = res.test
    df = float(te.f[1] - te.f[0])
    ker = kernel(res.nperseg)
    bound = float(stats.chi2.isf(alpha, 3))
    H1 = model_response(full, te.f, sig.dt, df, ker)
    d1 = departure(te, H1, res.usable_test, alpha, res.noise_psd)
    for j, i in enumerate(idx):
        hz = full.modes[j][0]
        without = Plant(full.J, full.B, full.K, full.delay_s, [m for k, m in enumerate(full.modes) if k != j])
        H0 = model_response(without, te.f, sig.dt, df, ker)
        d0 = departure(te, H0, res.usable_test, alpha, res.noise_psd)
        near = res.usable_test & (np.abs(te.f - hz) <= 2 * df)
        sd = deviation(te, H0, None)
        own = np.maximum(np.abs(H1 - H0) - bias(te, H0, res.noise_psd) * np.abs(H0), 0.0) / np.maximum(sd, 1e-300)
        visible = bool(np.any(near & (own**2 > d0["bound"]))) if d0["bound"] else False
        gain = d0["sse"] - d1["sse"]
        ev = {"test": "held-out frequency response with and without the mode (sum of z2, chi-square bound of 3 "
                      "parameters)", "test_sse_without": d0["sse"], "test_sse_with": d1["sse"], "bound": bound,
              "usable_bins_near": int(near.sum()), "visible": visible, "band_hz": res.band_hz,
              "rows_edge_hz": float(edge)}  # fmt: skip
        if near.any() and gain > bound:
            ev["rule"], ok = "shown", True
        elif visible:
            ev["rule"], ok = "contradicted", False
            ev["reason"] = (f"the recording's own frequency response does not show it: it would stand out in "
                            f"{int(near.sum())} usable bins within 2 bins of {hz:.4g} Hz, and the held-out departure "
                            f"is {d0['sse']:.4g} without it, {d1['sse']:.4g} with it (it must fall by more than "
                            f"{bound:.3g})")  # fmt: skip
        else:
            ev["rule"], ok = "not resolved", hz < edge
            if not ok:
                ev["reason"] = (f"neither the rows (band edge {edge:.4g} Hz) nor the frequency response ({int(near.sum())} "
                                f"usable bins within 2 bins of {hz:.4g} Hz, departure {d0['sse']:.4g} without it and "
                                f"{d1['sse']:.4g} with it) resolve it")  # fmt: skip
        out.append((i, ok, ev))
    return out


__all__ = ["COH_MIN", "MAX_MODES", "MIN_BINS", "Mode", "Plant", "REL_MARGIN", "Response", "Result",
           "choose_nperseg", "departure", "input_path", "measure", "model_response", "path_terms", "run",
           "sliding_segments", "support"]

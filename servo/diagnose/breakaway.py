"""Breakaway friction above the sliding level, from the intervals at rest.

A friction that is higher only at rest (Karnopp: the arm stays put while the net force
is within the breakaway level ``Fs``, and slides against ``Fc < Fs`` once it moves)
shows where the force-balance rows cannot look: the rows within the decimation
filter's reach of a sample whose direction is uncertain are unusable by construction
(docs/diagnosis.md, section 1), so the rows see only the filtered tails of each
breakaway transient, and no column of the vocabulary describes those tails (a
``stribeck_friction`` with a Stribeck velocity below every usable row's speed
explained 40 % of one such recording's cross-validated error, in a few blocks).

The evidence here is the force the friction must hold at each **event** (a run of
samples where the filtered velocity is within its noise or changes sign, widened by
:data:`WIDEN` Butterworth time scales):

    f(t) = B(u_eff)(t) - sum over the model's non-friction column terms of coef*column(t)

(``B`` the position's zero-phase Butterworth, the columns built from the filtered
motion: ``f`` is the friction force through the same filter, ``J*x''`` included, so
while the arm is stuck it is the held net force ``u - K*x - h0`` and while it slides
the sliding friction).  Under the model without breakaway (Coulomb friction with
sticking at ``Fs = Fc``) the friction never exceeds ``Fc`` in magnitude: ``|f|`` stays
within ``Fc`` through the filter (``L1*Fc`` at worst, :func:`filter_l1`, the 1-norm of
its impulse response; in practice the overshoot of the sliding level's switch at the
reversal).  With breakaway the arm holds forces up to ``Fs`` before it moves.  Per event
the statistic is its peak ``|f|``; an event **exceeds** when the peak is beyond

    g*(Fc + Z_FC*std(Fc)) + MARGIN*Fc + REL_FORCE*max|B(u)| + noise

with ``g`` the largest ``|B(sgn(x'))|`` in the window (the switch of the sliding level
through the filter, its overshoot included), ``max|B(u)|`` the largest input force in it
(the model's error grows with the force it explains: a closed loop's kick from rest,
:data:`REL_FORCE`), ``noise`` the ``1 - P_NOISE`` quantile of
the largest ``|f - Fc*sgn(x')|`` over windows of the event's width where the arm slides,
**near the event** (the :data:`LOCAL_WINDOWS` nearest such windows: a misfit elsewhere,
an open loop's PRBS kicks, does not raise every event's bound; :func:`noise_max`; a
quantised sensor's step pulse added, :func:`step_pulse`), **and**
the peak is a breakaway: it comes from rest and points where the arm then moves
(:func:`_toward`), or it is held inside a rest of :data:`REST_MIN` time scales (the arm
held against it, whichever way it then leaves: :func:`_held`).  The peak is read near
the event's last departure from rest (:func:`departures`; docs/diagnosis.md, 4b), where
a breakaway's held force peaks, and compared with sliding windows of that width, not of
the whole hold.  Under the null an event exceeds with probability at most
:data:`P_EXCEED`.  The test no longer counts exceedances (docs/diagnosis.md, 4b): each
event gets a p-value, its peak's excess over ``g*(Fc + Z_FC*std(Fc)) + MARGIN*Fc``
against the local law of the same window maximum (at least uniform under the null), and
the training part's ``N`` p-values are combined (their truncated product,
:mod:`servo.diagnose.breakaway_evidence`), so that three
events far beyond their noise prove a breakaway, and twenty each a little beyond do too;
``k`` counts the events at ``p <= TAU``.  It is one candidate of the vocabulary round in which ``stribeck_friction`` may
be tried (the round's family-wise level is shared with it: :func:`applicable`), and it
is tried only after the rows' rounds, on the model they ended with, so that a
hysteresis or a delay the rows name first is in the model the held forces are
computed with.

**Fit**: ``Fs`` is the median peak of the training part's ``k`` events (a peak
is the held force through the low-pass: a breakaway held for longer than the filter's
time scale shows at its level, a shorter one below it), with the standard deviation of
that median (``1.2533*std/sqrt(k)``).  The Stribeck velocity is the
smallest speed the data resolve, the direction threshold (``3`` noise std of the
filtered velocity): a breakaway faster than that is a step at rest.

**Proof** on the held-out part: its own events' p-values, combined the same way, must
be below ``alpha`` (no search), and the median peak of its events at ``p <= TAU`` must lie
above the sliding level's bound with a noise margin of ``Z_NOISE`` robust std
(``level_bound``): "the test part's stuck intervals hold forces in ``(Fc, Fs]``".  (In
practice the proof is the combined p-value.)  The
finding's before/after errors are the held-out events' RMS excess over the model's
static level through the filter (``g*Fc`` without, ``g*Fs`` with the finding).

**A held-out part that hardly rests** (a chirp rising past the sticking speeds: every
held-out event passes through zero speed without a hold of :data:`REST_MIN` Butterworth
time scales, :func:`dwell`; seek strokes whose held-out part holds one or two rests:
fewer than :data:`MIN_REST_TEST`) cannot show a breakaway on its own, so its failure to
confirm one says little.  There (and only there, a rule on the velocity, not on the forces) a finding
the held-out part does not confirm gets a second, stated proof: the training events are
split alternately, the test (at the same level) and the fit of ``Fs`` run on one half,
and the other half must confirm it as the held-out part would.  Both halves are training
events, so this proof is on events its test and fit did not use, not on a later part of
the recording; the report says which proof was used (``proof``).  The first test on all
training events must pass too, so the split adds no false alarm beyond that test's
level.  When neither proves it, the finding is listed as not confirmed with the reason
that the held-out part could not test it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from scipy import signal
from scipy.ndimage import maximum_filter1d

from servo.diagnose.breakaway_evidence import TAU, combine, event_pvalues, nearest, window_lengths
from servo.diagnose.signals import butter_ba
from servo.physics import EFFECTS, diagnosed_by

#: the term a breakaway at rest is (the effect that registers this stage) and the
#: sliding level it rises from (the term it requires)
BREAKAWAY = diagnosed_by("breakaway")
SLIDING = EFFECTS[BREAKAWAY].term.search.requires[0]

#: an event's window reaches this many Butterworth time scales (``fs/cutoff`` samples) past its run
WIDEN = 2.0
#: noise margin of the bound, in robust standard deviations of the held force
Z_NOISE = 3.0
#: margin on the Coulomb level's uncertainty, in its standard deviations
Z_FC = 2.0
#: practical margin: an excess below this fraction of ``Fc`` is not counted
MARGIN = 0.05
#: the noise margin is this upper quantile of the noise's maximum over a window (:func:`noise_max`)
P_NOISE = 0.01
#: probability that one event of a null recording exceeds the bound (its noise margin is
#: the :data:`P_NOISE` quantile of the window maximum, with a factor 2 to spare)
P_EXCEED = 0.02
#: fewer training events than this: not testable (the combined p-value holds its level for any
#: number of events; three far beyond their noise prove a breakaway, docs/diagnosis.md 4b)
MIN_EVENTS = 3
#: the local noise margin (:func:`noise_max`) is taken over the sliding windows within
#: this many window widths around each event (about as many independent windows)
LOCAL_WINDOWS = 100
#: an event is **at rest** when its filtered velocity stays within its noise for at
#: least this many Butterworth time scales (a hold long enough to show a breakaway)
REST_MIN = 0.3
#: a held-out part with fewer events at rest than this cannot test a breakaway on its own
#: (one or two holds, a seek's last stroke): the split proof on training events is stated instead
MIN_REST_TEST = 3
#: the model's error in the held force, per unit of the largest force the input applies
#: in the event's window (``|B(u)|``): a fit's error is proportional to the force it
#: explains (a relative error in ``J``, a kick's timing), not constant.  A closed loop's
#: reference step kicks the arm from rest with 0.3-3 A against a Coulomb level of 2e-5 A
#: and leaves 1.2-4.2e-4 of the kick in the held force of a null (development seeds);
#: a breakaway holds a force of the order of the input's (0.3-2.7 of it on Karnopp
#: recordings), so this margin is 1e-3 of the input's force there and does not hide it
REL_FORCE = 1e-3


@lru_cache(maxsize=16)
def filter_l1(order: int, wn: float) -> float:
    """1-norm of the zero-phase Butterworth's impulse response (its worst-case gain for a
    bounded input: a force within ``+-F`` stays within ``+-L1*F`` through it)."""
    b, a = butter_ba(order, wn)
    n = int(40 / wn) + 101
    z = np.zeros(2 * n + 1)
    z[n] = 1.0
    return float(np.abs(signal.filtfilt(b, a, z, padlen=3 * order)).sum())


def noise_max(abs_e: np.ndarray, outside: np.ndarray, widths: np.ndarray, sigma: float,
              centres: np.ndarray | None = None) -> np.ndarray:
    """The noise margin of each event (F, (N,)): the ``1 - P_NOISE`` quantile of the
    largest ``|f - Fc*sgn(x')|`` over windows of the event's width (rounded up to a power
    of two) where the arm slides, outside every event: the recording's own noise and
    misfit, its tails and correlation included (a quantised sensor's pulses are not
    Gaussian; a window of thousands of samples reaches further into them than one of
    forty).  ``Z_NOISE*sigma`` at least, and where the sliding part has too few such
    windows.

    With ``centres`` (full-rate samples, (N,)) the quantile is **local**: over the
    sliding windows within :data:`LOCAL_WINDOWS` window widths of the event's centre
    (the nearest ones, the neighbourhood widened until it holds that many), so that a
    misfit elsewhere in the recording (an open loop's PRBS kicks, a chirp's fast end)
    does not raise every event's bound; the recording's quantile where the sliding part
    holds fewer windows than that."""
    z = np.where(outside, abs_e, np.inf)
    out = np.full(widths.size, Z_NOISE * sigma)
    L_of = window_lengths(widths)
    for L in np.unique(L_of):
        m = maximum_filter1d(z, size=int(L), mode="constant", cval=np.inf)
        ok = np.isfinite(m)
        if np.count_nonzero(ok) < 20 * L:
            continue
        sel = np.flatnonzero(L_of == L)
        if centres is None:
            out[sel] = max(float(np.quantile(m[ok], 1.0 - P_NOISE)), Z_NOISE * sigma)
            continue
        pos = np.flatnonzero(ok)
        need = int(min(LOCAL_WINDOWS * L, pos.size))
        done: dict = {}  # per neighbourhood: events share one near the ends, or all of them in a short recording
        for j in sel:
            sl = nearest(pos, centres[j], need)
            if (sl.start, sl.stop) not in done:
                done[sl.start, sl.stop] = max(float(np.quantile(m[pos[sl]], 1.0 - P_NOISE)), Z_NOISE * sigma)
            out[j] = done[sl.start, sl.stop]
    return out


@dataclass
class Events:
    """Windows around the samples at rest or reversing: ``start``, ``stop`` (full-rate
    sample range, (N,)), ``peak`` the largest ``|f|`` in each (F), ``train`` whether the
    window lies in the training part, ``bound`` each one's (F), ``toward`` whether its
    peak force points in the direction the arm then moves."""

    start: np.ndarray
    stop: np.ndarray
    peak: np.ndarray
    train: np.ndarray
    bound: np.ndarray
    toward: np.ndarray
    #: (N,) whether the arm is held at rest in the window (:func:`dwell`, :data:`REST_MIN`)
    still: np.ndarray | None = None
    #: (N,) each event's p-value against its local noise (:mod:`servo.diagnose.breakaway_evidence`)
    pvalue: np.ndarray | None = None


@dataclass
class Result:
    """The breakaway test on one model: the bound (F), the events, the training
    part's exceeding count ``k`` of ``n``, its ``p``; the fit (``Fs``, ``Fs_std``,
    ``Fc``) and the held-out part's ``k_test`` of ``n_test`` and ``p_test``."""

    bound: float = 0.0
    #: the sliding level's bound without the window maximum's margin, ``Z_NOISE`` robust
    #: std instead (F; median over the events): the proof's typical held force must pass it
    level_bound: float = 0.0
    sigma: float = 0.0
    l1: float = 1.0
    Fc: float = 0.0
    Fc_std: float = 0.0
    n: int = 0
    k: int = 0
    p: float = 1.0
    n_test: int = 0
    k_test: int = 0
    p_test: float = 1.0
    Fs: float = 0.0
    Fs_std: float = 0.0
    Fs_test: float = 0.0
    excess_before: float = 0.0
    excess_after: float = 0.0
    #: where the finding is proven: the held-out part's events, or (where that part
    #: holds fewer than MIN_REST_TEST intervals at rest) the training events held out from the fit of ``Fs``
    proof: str = "held-out part"
    #: the held-out part's events at rest (:data:`REST_MIN`)
    n_rest_test: int = 0
    #: ``p`` over every training event (``p`` itself is over the events the test ran on)
    p_all: float = 1.0
    #: where the held-out part holds fewer than :data:`MIN_REST_TEST` events at rest: the
    #: same test with ``Fs`` fitted on every other training event and proven on the
    #: others (module doc, "Proof")
    split: "Result | None" = field(default=None, repr=False)
    note: str = ""
    events: Events | None = field(default=None, repr=False)

    #: the training part's events (``n`` counts those the test ran on: all of them, or
    #: every other one where the proof is on the others)
    n_train: int = 0

    @property
    def testable(self) -> bool:
        return self.n_train >= MIN_EVENTS

    def passes(self, level: float) -> bool:
        return self.testable and self.p < level

    def confirmed(self, alpha: float) -> bool:
        return self.k_test > 0 and self.p_test < alpha and self.Fs_test > self.level_bound

    def evidence(self) -> dict:
        """The report's evidence.  The ``*_test`` keys are the events of the proof
        (``proof``): the held-out part's, or, where it holds fewer than :data:`MIN_REST_TEST` intervals at rest, the
        training events the fit did not use (``held_excess_rms`` of the finding's
        errors is over the same events)."""
        return {"test": "held forces at rest beyond the sliding level (per-event p-values against the local noise, "
                        "combined: truncated product)",
                "bound": self.bound, "level_bound": self.level_bound, "sigma": self.sigma, "filter_l1": self.l1, "Fc": self.Fc,
                "events_train": self.n, "exceeding_train": self.k, "exceeding_at_event_p": TAU, "p": self.p,
                "events_test": self.n_test, "exceeding_test": self.k_test, "p_test": self.p_test,
                "Fs_test": self.Fs_test, "proof": self.proof, "events_at_rest_heldout": self.n_rest_test,
                "p_all_training": self.p_all}  # fmt: skip


def applicable(model, candidates) -> bool:
    """Whether the breakaway test shares the round of ``candidates`` (``stribeck_friction``
    among them: the model has a Coulomb friction and no Stribeck term yet)."""
    return BREAKAWAY in candidates


def held_force(design, fit) -> np.ndarray:
    """``f`` (n,): the friction force through the position's Butterworth, what the
    recorded force leaves after every non-friction column term of ``fit`` (module doc)."""
    from servo.diagnose.terms import VOCABULARY

    sig = design.sig
    f = sig.force(design.u_eff(fit.model)).copy()
    for i, t in enumerate(fit.model.terms):
        if VOCABULARY[t.physics].path.kind != "column" or t.physics in (SLIDING, BREAKAWAY):
            continue
        # as the force balance of the measured motion sees it: through a sensor lag the
        # model holds, zero before a gated term's onset (Design.full_columns)
        f -= design.full_columns(t, fit.model) @ np.asarray(fit.coefs[i], dtype=float)
    return f


def sliding_sign(design, fit, ci: int) -> np.ndarray:
    """(n,) the sliding level's switch per unit ``Fc``: the Coulomb column of ``fit``
    (term ``ci``) at full rate, ``sgn(x')`` at the lag-corrected velocity's crossings and
    through the sensor's low-pass where the model holds a sensor lag
    (:class:`servo.diagnose.sensor_lag.LaggedSignals`), the recording's sign otherwise."""
    return design.full_columns(fit.model.terms[ci], fit.model)[:, 0]


def events(sig) -> tuple[np.ndarray, np.ndarray]:
    """Full-rate windows ``(start, stop)`` around every run of samples where the filtered
    velocity is within its noise or changes sign, widened by :data:`WIDEN` Butterworth
    time scales and merged where they overlap; windows reaching the trimmed ends are dropped."""
    n = sig.vf.size
    mark = marks(sig)
    d = np.diff(np.r_[0, mark.astype(np.int8), 0])
    a, b = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    if a.size == 0:
        return a, b
    fs = 1.0 / sig.dt
    w = int(np.ceil(WIDEN * fs / sig.settings.cutoff(fs)))
    a, b = np.maximum(a - w, 0), np.minimum(b + w, n)
    keep_a, keep_b = [a[0]], [b[0]]
    for s, e in zip(a[1:], b[1:]):
        if s <= keep_b[-1]:
            keep_b[-1] = max(keep_b[-1], e)
        else:
            keep_a.append(s)
            keep_b.append(e)
    a, b = np.array(keep_a), np.array(keep_b)
    st = sig.settings
    ok = (a >= st.trim_start) & (b <= n - st.trim_end)
    return a[ok], b[ok]


def marks(sig) -> np.ndarray:
    """(n,) samples at rest or reversing: the filtered velocity within its noise or
    changing sign."""
    v = sig.vf
    m = np.abs(v) <= sig.v_threshold
    m[1:] |= np.sign(v[1:]) * np.sign(v[:-1]) < 0
    return m


def dwell(sig, a: np.ndarray, b: np.ndarray, runs: tuple | None = None) -> np.ndarray:
    """(N,) the longest run of samples of each event ``[a, b)`` where the filtered
    velocity is within its noise (samples): how long the arm was held there.  A
    reversal that passes through zero without a hold has a run of 0-1 samples.
    ``runs``: those runs over the recording (:func:`still_runs`), if found already."""
    up, dn = runs if runs is not None else still_runs(np.abs(sig.vf) <= sig.v_threshold)
    out = np.zeros(a.size, int)
    for j, (s, e) in enumerate(zip(a, b)):
        k0, k1 = int(np.searchsorted(dn, s, side="right")), int(np.searchsorted(up, e, side="left"))
        if k1 > k0:  # the runs that overlap the event, clipped to it
            out[j] = int((np.minimum(dn[k0:k1], e) - np.maximum(up[k0:k1], s)).max())
    return out


def departures(sig, a: np.ndarray, b: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full-rate windows ``(start, stop)`` ((N,) each) where each event's breakaway would
    show: :data:`WIDEN` Butterworth time scales either side of the event's last departure
    from rest (the first sample after its last run of ``rest``, :func:`marks`), within the
    event.  A breakaway's held force peaks there (the arm stays put until the net force
    reaches ``Fs``, then slides against ``Fc``), so the event's statistic is read there and
    compared with sliding windows of that width, not of the whole hold (a hold of 1500
    samples among few sliding samples was compared, by the union bound, with noise it
    could never beat; docs/studies/2026-11-24-karnopp-departures.md).  An event without a departure (its run of
    rest reaches its end) keeps its whole window."""
    fs = 1.0 / sig.dt
    w = int(np.ceil(WIDEN * fs / sig.settings.cutoff(fs)))
    da, db = a.copy(), b.copy()
    for j, (s, e) in enumerate(zip(a, b)):
        r = rest[s:e]
        out = np.flatnonzero(r[:-1] & ~r[1:])  # last rest sample before a moving one
        if out.size == 0:
            continue
        d = s + int(out[-1]) + 1
        da[j], db[j] = max(s, d - w), min(e, d + w + 1)
    return da, db


def _held(runs: tuple[np.ndarray, np.ndarray], i: int, hold: float) -> bool:
    """Whether sample ``i`` lies inside a run of samples with the filtered velocity within
    its noise (``runs``: their starts and stops, :func:`still_runs`) at least ``hold``
    samples long: the arm held at rest there, so a force beyond the sliding level at ``i``
    is held by static friction whichever way the arm then moves (a pulse train's input
    flips while the arm is held: it leaves the other way)."""
    up, dn = runs
    k = int(np.searchsorted(up, i, side="right")) - 1
    return k >= 0 and i < dn[k] and dn[k] - up[k] >= hold


def still_runs(still: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and stops ((R,) each, stop exclusive) of the runs of ``still`` ((n,) bool)."""
    d = np.diff(np.r_[0, still.astype(np.int8), 0])
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def rest_neighbours(rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(last, first_move)`` ((n,) int each) of the rest marks ``rest`` ((n,) bool,
    :func:`marks`): ``last[i]`` the latest sample at or before ``i`` at rest (-1: none),
    ``first_move[k]`` the first sample at or after ``k`` not at rest (``n``: none).  Two
    running extrema, so that every event's :func:`_toward` is a lookup rather than a scan
    of the rest of the recording."""
    n = rest.size
    idx = np.arange(n)
    last = np.maximum.accumulate(np.where(rest, idx, -1))
    first_move = np.minimum.accumulate(np.where(rest, n, idx)[::-1])[::-1]
    return last, first_move


def _toward(f: np.ndarray, v: np.ndarray, near: tuple[np.ndarray, np.ndarray], s: int, i: int) -> bool:
    """Whether the peak held force ``f[i]`` of the event starting at ``s`` is a breakaway:
    it comes at or after a sample at rest, and points where the arm moves when it leaves
    the last rest before it (``near``: :func:`rest_neighbours` of the rest marks).  A
    force that peaks while the arm still approaches a reversal (a lag or a hysteresis the
    model has wrong) is not one."""
    last, first_move = near
    r = int(last[i])
    if r < s:
        return False
    k = int(first_move[r])
    if k >= f.size:
        return False
    return bool(np.sign(f[i]) == np.sign(v[k]))


@lru_cache(maxsize=16)
def _step_accel(order: int, wn: float) -> float:
    """Largest ``|x''|`` (per unit step, per sample^2) the path makes of one position
    step: the Butterworth's step response, second-differenced."""
    from servo.diagnose.signals import second_difference

    b, a = butter_ba(order, wn)
    n = int(40 / wn) + 101
    z = (np.arange(2 * n + 1) >= n).astype(float)
    return float(np.abs(second_difference(signal.filtfilt(b, a, z, padlen=3 * order), 1.0)).max())


def step_pulse(sig, fit, step: float) -> float:
    """The force pulse ``|J|*step*max|x''|`` one quantum of a quantised sensor makes in
    the held force (F): near rest the position crosses the lattice one step at a time,
    each a pulse that no sliding window shows (0 without a lattice)."""
    if not step > 0:
        return 0.0
    J = abs(float(fit.mass()))
    fs = 1.0 / sig.dt
    return J * step * _step_accel(int(sig.settings.butter_order), float(sig.settings.cutoff(fs) / (fs / 2))) / sig.dt**2


def _score(res: Result, over: np.ndarray, peak: np.ndarray, ref: np.ndarray, sigma: float, fit_ev: np.ndarray,
           proof_ev: np.ndarray, pv: np.ndarray) -> None:
    """Fill ``res``'s test (``k`` of ``n``, ``p``) and fit (``Fs``) on the events
    ``fit_ev`` and its proof (``k_test`` of ``n_test``, ``p_test``, ``Fs_test``, the
    excess before and after) on the events ``proof_ev`` ((N,) masks): ``p`` and
    ``p_test`` combine the events' p-values ``pv`` ((N,),
    :func:`servo.diagnose.breakaway_evidence.combine`), ``over`` ((N,)) the events beyond
    their noise at :data:`~servo.diagnose.breakaway_evidence.TAU` (counted, and the fit's)."""
    Fc = res.Fc
    res.n, res.n_test = int(fit_ev.sum()), int(proof_ev.sum())
    res.k, res.k_test = int((over & fit_ev).sum()), int((over & proof_ev).sum())
    res.p = combine(pv[fit_ev]) if res.n else 1.0
    res.p_test = combine(pv[proof_ev]) if res.n_test else 1.0
    res.Fs = res.Fs_std = res.Fs_test = 0.0
    if res.k:
        pk = peak[over & fit_ev]
        res.Fs = float(np.median(pk))
        res.Fs_std = float(1.2533 * pk.std(ddof=1) / np.sqrt(pk.size)) if pk.size > 1 else float(sigma)
    if res.k_test:
        res.Fs_test = float(np.median(peak[over & proof_ev]))
    if res.n_test:
        pt, gt = peak[proof_ev], ref[proof_ev]
        res.excess_before = float(np.sqrt(np.mean(np.maximum(pt - gt * Fc, 0.0) ** 2)))
        res.excess_after = float(np.sqrt(np.mean(np.maximum(pt - gt * max(res.Fs, Fc), 0.0) ** 2)))


def test(design, fit, step: float = 0.0) -> Result:
    """The breakaway test of ``fit`` (its model must hold ``coulomb_friction``), its fit and
    its held-out proof (module doc); ``step`` the position quantum of a quantised sensor
    (0: none), whose pulses near rest are added to the bound (:func:`step_pulse`)."""
    sig = design.sig
    res = Result()
    ci = next((i for i, t in enumerate(fit.model.terms) if t.physics == SLIDING), None)
    if ci is None:
        res.note = f"needs {SLIDING} in the model"
        return res
    Fc = float(fit.combined()[SLIDING]["Fc"])
    Fc_std = float(fit.term_std(ci).get("Fc", 0.0)) if fit.model.terms[ci].free else 0.0
    if not Fc > 0:
        res.note = "the Coulomb level is not positive"
        return res
    f = held_force(design, fit)
    a, b = events(sig)
    fs = 1.0 / sig.dt
    l1 = filter_l1(int(sig.settings.butter_order), float(sig.settings.cutoff(fs) / (fs / 2)))
    # the noise of f where the arm slides, outside every event
    outside = np.ones(sig.n, bool)
    st = sig.settings
    outside[: st.trim_start] = outside[sig.n - st.trim_end :] = False
    for s, e in zip(a, b):
        outside[s:e] = False
    if np.count_nonzero(outside) < 100:
        res.note = "the arm is hardly ever sliding away from a reversal"
        return res
    sgn = sliding_sign(design, fit, ci)
    e = f - Fc * sgn
    sigma = float(1.4826 * np.median(np.abs(e[outside] - np.median(e[outside]))))
    g = np.abs(sig.butter(sgn))  # the sliding level's switch through the filter, per unit Fc
    rest = marks(sig)
    da, db = departures(sig, a, b, rest)  # where each event's breakaway shows
    ref = np.array([g[s:e_].max() for s, e_ in zip(da, db)]) if a.size else np.zeros(0)
    noise = noise_max(np.abs(e), outside, db - da, sigma, (da + db) // 2)
    pulse = step_pulse(sig, fit, step)
    # the bound's deterministic part: the sliding level's switch, its margins, and the
    # model's error in proportion to the input's force at the event (REL_FORCE)
    F = np.abs(sig.force())
    model_err = REL_FORCE * np.array([F[s:e_].max() for s, e_ in zip(da, db)]) if a.size else np.zeros(0)
    fixed = ref * (Fc + Z_FC * Fc_std) + MARGIN * Fc + model_err
    bound = float(np.median(fixed + noise)) if a.size else 0.0
    bounds = fixed + noise + pulse
    res.level_bound = float(np.median(ref)) * (Fc + Z_FC * Fc_std) + MARGIN * Fc + Z_NOISE * sigma + pulse if a.size else 0.0
    peak, toward = np.zeros(a.size), np.zeros(a.size, bool)
    runs = still_runs(np.abs(sig.vf) <= sig.v_threshold)
    hold = REST_MIN * fs / sig.settings.cutoff(fs)
    near = rest_neighbours(rest)
    for j, (s, s_, e_) in enumerate(zip(a, da, db)):
        i = s_ + int(np.argmax(np.abs(f[s_:e_])))
        peak[j] = abs(f[i])
        # a peak held inside a rest counts whichever way the arm then moves (_held)
        toward[j] = _toward(f, sig.vf, near, s, i) or _held(runs, i, hold)
    still = dwell(sig, a, b, runs) >= hold
    last = int(np.flatnonzero(design.train_samples)[-1])
    train = b <= last
    test_ = a > last
    # each event's p-value: its excess over the sliding level's switch and margins against
    # the local window maximum of the sliding misfit (breakaway_evidence)
    excess = peak - (fixed + pulse)
    pv = event_pvalues(np.abs(e), outside, db - da, (da + db) // 2, excess, toward, LOCAL_WINDOWS) if a.size else np.ones(0)
    res.events = Events(a, b, peak, train, bounds, toward, still, pv)
    res.bound, res.sigma, res.l1, res.Fc, res.Fc_std = bound, sigma, l1, Fc, Fc_std
    res.n_rest_test = int((still & test_).sum())
    over = (pv <= TAU) & toward
    res.n_train = int(train.sum())
    _score(res, over, peak, ref, sigma, train, test_, pv)
    res.p_all = res.p
    if res.n_rest_test < MIN_REST_TEST and res.n_train >= MIN_EVENTS:
        # the held-out part holds fewer than MIN_REST_TEST intervals at rest (a chirp past
        # the sticking speeds, a seek's last stroke): it cannot show a breakaway on its own.  The alternative proof: the test and the fit of Fs
        # on every other training event, the proof on the others (module doc, "Proof")
        idx = np.flatnonzero(train)
        fit_ev, proof_ev = np.zeros(a.size, bool), np.zeros(a.size, bool)
        fit_ev[idx[0::2]], proof_ev[idx[1::2]] = True, True
        res.split = replace(res, proof="training events held out from the fit", split=None)
        _score(res.split, over, peak, ref, sigma, fit_ev, proof_ev, pv)
    if not res.testable:
        res.note = f"{res.n_train} events at rest or reversing in the training part (need {MIN_EVENTS})"
    return res


__all__ = ["Events", "MIN_EVENTS", "REL_FORCE", "Result", "applicable", "events", "filter_l1", "held_force", "marks", "noise_max", "sliding_sign", "step_pulse", "dwell",
           "departures", "rest_neighbours", "still_runs",
           "test"]

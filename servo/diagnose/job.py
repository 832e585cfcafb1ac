"""One diagnosis, from a recording to findings: baseline, locate, name, model and prove.

A recording outside the domain (:mod:`servo.diagnose.scope`) stops at the first stage
that measures it, with the verdict ``out_of_scope`` and its reason.

1. **Baseline** (:mod:`servo.diagnose.baseline`): a term set fitted on the training
   part (the first ``1 - test_fraction`` of the rows) or a fixed model file.
2. **Locate** (:mod:`servo.diagnose.locate`): the baseline's held-out residual, tested
   in time, state and frequency.
3. **Name** (:mod:`servo.diagnose.select`): every eligible vocabulary term scored by
   blocked cross-validation on the training part; the best that pays is added, until
   none does.  Quantisation is tested apart (:mod:`servo.diagnose.quantization`).
   Then, if the training part's residual is still located in time, the terms gated in
   time (present from an onset on, :mod:`servo.diagnose.partial`).
4. **Model and prove**: each finding in turn is added to the model fitted on the
   training part and judged on the *test* part, which no choice has seen: force
   residual relative error and short-horizon simulated-output NRMSE
   (:mod:`servo.diagnose.simulate`), before -> after.  A finding that does not lower the
   test part's force error, or raises its output NRMSE by more than 5 % consistently
   over the test part's starts (:func:`output_worse`), is not confirmed: it is dropped
   from the findings and the model and reported as such.
   One name per effect: a finding beside the first must also pass the sign-flip test
   of its gain on the test part (:func:`~servo.diagnose.select.heldout_signflip`, its
   ``p`` reported as its chance of being spurious), no finding keeps unphysical
   parameters in the final model, every finding must remove :data:`SHARE` of the
   held-out residual the model before it leaves above the noise floor
   (:func:`material_share`; of two names of one effect the weaker is dropped), and
   where the baseline already passes every check of the verdict a finding must remove
   :data:`MATERIAL` of the held-out residual.
   A quantised sensor is tested first, since its finding changes the rows everything
   else is computed on.
   A breakaway above the sliding friction (:mod:`servo.diagnose.breakaway`) is tested
   on the intervals at rest, which the rows cannot use, on the final model of the rows
   (one share of the Stribeck round's level), and proven on the test part's own.
5. **Above the rows' band** (:mod:`servo.diagnose.frf_modes`): the input-to-position
   frequency response at the full sample rate against the model's, modes fitted where
   it departs, each proven on the test part's own response and on the output NRMSE.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field, replace

import numpy as np
from threadpoolctl import threadpool_limits

from servo.diagnose import baseline as baseline_mod
from servo.diagnose import breakaway as breakaway_mod
from servo.diagnose import frf_modes
from servo.diagnose.band import CANDIDATES, dithered
from servo.diagnose.band import choose as choose_band
from servo.diagnose import locate
from servo.diagnose import partial
from servo.diagnose import verdict as verdict_mod
from servo.diagnose.fit import Fit, fit_model, force_error_pct
from servo.diagnose.model import ROWS_BUDGET, Design, Model, Term
from servo.diagnose.scope import OutOfDomain, Unscoped
from servo.diagnose.quantization import (MIN_FRACTION, SHARE_MIN, Lattice, acceleration_share, attenuated_inertia,
                                         candidate_paths, error_share, heldout_on_lattice, improvement_test,
                                         lattice_test, quantum_floor, scope_reason)
from servo.diagnose.select import (ALPHA, HELDOUT_BLOCKS, N_BLOCKS, Grams, Score, Selector, heldout_signflip,
                                   integrated_time, make_blocks, signflip_test)
from servo.diagnose.signals import Signals, distance_since_reversal, make_signals
from servo.diagnose.simulate import Prediction, Unsimulable, horizon_samples, predict, starts_in
from servo.diagnose.terms import VOCABULARY
from servo.errors import ServoError
from servo.physics import EFFECTS, diagnosed_by
from servo.identify.regressors import IdentificationError, RobustSettings
from servo.io import progress
from servo.io.recording import Recording
from servo.io.resources import available_memory

MIN_ROWS_PER_BLOCK = 20
#: memory a diagnosis needs (:func:`memory_estimate`): bytes per full-rate sample (the
#: filtered motion, two effective inputs, the filters' temporaries, a second path's
#: signals after a quantisation finding) and per row (the cached candidate columns and
#: a chunk of screened variants); measured 310-340 B per sample in all at decimation by 10
#: (``python -m studies.memprobe``), estimated with a margin; 224 since the noise floor's
#: spectrum, the frequency evidence over the excited band and the drift came in (a
#: 200 000-sample diagnosis peaked at 83-84 MB beside the recording, over the former 176's
#: 79.3 MB; measured by ``tests/test_diagnose_memory.py``)
BYTES_PER_SAMPLE = 224
BYTES_PER_ROW = 2400
#: of :data:`BYTES_PER_ROW`, the cached columns' share, which
#: :data:`servo.diagnose.model.ROWS_BUDGET` bounds (1342 B a row measured at 1e6 samples
#: and decimation by 10: 128 MB of rows at the end of the rounds)
CACHE_BYTES_PER_ROW = 1400
#: a finding may not raise the held-out output NRMSE by more than this fraction
#: (consistently over the test part's starts: :func:`output_worse`)
OUTPUT_TOLERANCE = 0.05
#: on a baseline that passes every check of the verdict, a finding must remove at least
#: this share of the held-out residual RMS (the proving ground's effect threshold)
MATERIAL = 0.2
#: every finding, whatever the baseline's verdict, must remove at least this share of the
#: held-out residual RMS the model before it leaves above the noise floor, that excess
#: counted as at least :data:`EFFECT` of the floor (:func:`material_share`); fixed on
#: the development seeds (docs/studies/2026-11-28-material-findings.md)
SHARE = 0.15
#: the smallest excess over the noise floor the proving ground counts as an effect (an
#: effect changes the held-out error by 20 % or more)
EFFECT = 0.2
#: the terms the stages beside the selection rounds name, each the effect's that
#: registers the stage (:attr:`servo.physics.base.Effect.diagnosed_by`): the sensor's
#: lattice test, the breakaway test at rest, the frequency response above the rows' band
LATTICE, BREAKAWAY, FRF = diagnosed_by("lattice"), diagnosed_by("breakaway"), diagnosed_by("frf")


@dataclass
class Options:
    """What to diagnose with: ``baseline`` term set (``"J,B,Fc,K,h0"``) or ``model``
    file; ``test_fraction`` of the rows held out at the end; ``blocks`` of the
    cross-validation; ``alpha`` the family-wise false-alarm level; ``horizon_s`` of
    the output simulation (default 10 row spacings); the robust path's ``settings``
    (None: the decimation is chosen from the recording, :mod:`servo.diagnose.band`, by
    the rule ``band``, with the Butterworth at ``cutoff_hz`` if given);
    at most ``max_findings``; ``force_unit`` and ``position_unit`` (m, or rad for a
    rotary axis) for the report."""

    baseline: str | None = None
    model: str | None = None
    test_fraction: float = 0.25
    blocks: int = N_BLOCKS
    alpha: float = ALPHA
    horizon_s: float | None = None
    settings: RobustSettings | None = None
    max_findings: int = 8
    force_unit: str = "A"
    position_unit: str = "m"
    cutoff_hz: float | None = None
    band: str = "reversals"


@dataclass
class Finding:
    """One named physics: its ``term`` (refined on the training part), the ``score``
    that admitted it, the test ``level`` it passed, the std of its nonlinear
    parameters; filled by the proof: errors before/after on the test part, where."""

    term: Term
    score: Score | None
    level: float
    theta_std: dict
    lattice: Lattice | None = None
    quant_test: tuple | None = None
    #: a quantum named on the default rows: its held-out evidence (:func:`_quantum_on_default_rows`)
    quant_heldout: dict | None = None
    before: dict = field(default_factory=dict)
    after: dict = field(default_factory=dict)
    where: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    std: dict = field(default_factory=dict)
    prediction: Prediction | None = None  # quantisation: the baseline's output on the default path
    frf: dict | None = None  # a mode of the frequency-domain path: its evidence (:mod:`servo.diagnose.frf_modes`)
    frf_support: dict | None = None  # a mode the rows named, held against the frequency response (_mode_support)
    #: an input-path term the frequency response named in place of the rows' (_input_path)
    frf_path: dict | None = None
    breakaway: dict | None = None  # a breakaway from the intervals at rest: its evidence (:mod:`servo.diagnose.breakaway`)
    #: the held-out sign-flip test against the model without it (:func:`servo.diagnose.select.heldout_signflip`):
    #: ``p`` its chance of being spurious, ``level`` the one it had to pass (None: the first finding)
    heldout: dict | None = None
    #: why the proof dropped it ("": it did not lower the held-out error)
    why: str = ""

    @property
    def physics(self) -> str:
        return self.term.physics

    @property
    def sensor(self) -> bool:
        """Whether the finding is the sensor's (a lattice): not a term of the force balance."""
        return VOCABULARY[self.physics].path.kind == "sensor"


@dataclass
class Diagnosis:
    """Everything a report and its plots need."""

    rec: Recording
    opt: Options
    sig: Signals
    design: Design
    baseline: Model
    baseline_fit: Fit
    final_fit: Fit
    findings: list
    unconfirmed: list
    rounds: list
    not_testable: dict
    implausible: dict  # passed the test, but the refined parameters do not describe the physics
    residual_before: np.ndarray  # held-out residual of the baseline (m,)
    residual_after: np.ndarray  # held-out residual of the final model (m,)
    test_rows: np.ndarray
    locate: dict
    state: dict
    pred_before: Prediction | None  # the baseline's (on the default path, if a quantisation finding moved the rows)
    pred_after: Prediction | None
    errors: dict
    lattice: Lattice
    simulate_note: str = ""
    #: ``{"verdict", "text", "baseline_checks", "final_checks"}`` (:mod:`servo.diagnose.verdict`)
    verdict: dict = field(default_factory=dict)
    #: why the rows' decimation (:mod:`servo.diagnose.band`)
    band_note: str = ""
    #: the frequency-domain path above the rows' band (:mod:`servo.diagnose.frf_modes`)
    frf: frf_modes.Result | None = None
    #: the model terms that path added (fitted on the frequency response, not the rows)
    frf_terms: list = field(default_factory=list)

    def _lines(self) -> list[str]:
        found = ", ".join(f.physics for f in self.findings) or "nothing beyond the baseline"
        err = self.errors.get("test_force_rel_pct")
        lines = [f"{self.rec.source}: {self.rec.n} samples; found {found}"]
        if self.verdict.get("verdict"):
            lines.append(f"verdict: {self.verdict['verdict']}")
        if isinstance(err, dict) and err:
            lines.append("held-out force error: " + ", ".join(f"{k} {v:.3g} %" for k, v in err.items()
                                                               if isinstance(v, (int, float))))  # fmt: skip
        return lines

    def __repr__(self) -> str:
        return "<Diagnosis " + "; ".join(self._lines()) + ">"

    def _repr_html_(self) -> str:
        """The summary lines as a report page's content (:mod:`servo.io.page`; the whole
        page of a folder is :func:`servo.diagnose.report.write_outputs`')."""
        from servo.io.page import Page

        status = verdict_mod.PAGE_STATUS.get(self.verdict.get("verdict"), "info")
        return Page("Diagnosis", self._lines(), status).fragment()


def heldout_residual(design: Design, model: Model, blocks, test_rows: np.ndarray) -> np.ndarray:
    """Residual rows of ``model`` where each training block is predicted by the fit on
    the other blocks and everything else by the fit on all training rows."""
    y, Phi, _ = design.matrix(model)
    fit = fit_model(design, model)
    r = fit.residual.copy()
    grams = Grams.of(Phi, y, blocks)
    for b, sl in enumerate(blocks.slices):
        c, _ = grams.fold(b)
        r[sl] = y[sl] - Phi[sl] @ c
    return r


def memory_estimate(n: int, opt: Options) -> float:
    """Bytes a diagnosis of ``n`` samples adds to the process (the recording excluded):
    linear in the samples and in the rows (``n/decimate``), the rows cache's share up to
    its bound (:data:`servo.diagnose.model.ROWS_BUDGET`)."""
    q = max(int(opt.settings.decimate if opt.settings is not None else CANDIDATES[0]), 1)
    rows = n / q
    cache = min(CACHE_BYTES_PER_ROW * rows, ROWS_BUDGET)
    return float(BYTES_PER_SAMPLE * n + (BYTES_PER_ROW - CACHE_BYTES_PER_ROW) * rows + cache)


def check_memory(n: int, opt: Options) -> None:
    """Refuse, in one line and before anything large is allocated, a recording whose
    diagnosis needs more memory than is available."""
    need = memory_estimate(n, opt)
    avail = available_memory()
    if avail is not None and need > avail:
        raise IdentificationError(
            f"diagnose: this recording of {n} samples needs about {need / 1e9:.2g} GB, {avail / 1e9:.2g} GB are "
            "available; diagnose a shorter part of it (cut the recording file) or free memory"
        )


def check_recording(rec: Recording) -> None:
    """Refuse what no diagnosis can use, in one line."""
    if np.ptp(rec.x) == 0:
        raise OutOfDomain("nothing excited: the position x is constant, there is no motion to diagnose")
    if np.ptp(rec.u) == 0:
        raise OutOfDomain("nothing excited: the input u is constant, there is no input to relate the motion to")


def state_variables(sig: Signals, pu: str = "m") -> dict:
    """Rows of the state variables residuals are binned by: name -> (values, sign, unit),
    positions in ``pu``."""
    s = np.sign(sig.v_rows)
    dist = distance_since_reversal(sig.xf, sig.vf, sig.v_threshold)[sig.keep]
    return {
        "position": (sig.x_rows, None, pu),
        "velocity": (sig.v_rows, None, f"{pu}/s"),
        "direction": (s, None, "-"),
        "distance_since_reversal": (dist, s, pu),
    }


def _select(sel: Selector, model: Model, opt: Options):
    """Greedy rounds, each at the family-wise level ``alpha`` over its candidates: first
    the corrections of a model file's terms (none for a fitted baseline), then the
    vocabulary's terms, so the terms are chosen among the same candidates, at the same
    level, whether the baseline is fitted or a file holds it (docs/diagnosis.md, 2)."""
    findings, rounds, not_testable, implausible = [], [], {}, {}
    for corrections in (True, False):
        model = _rounds(sel, model, opt, corrections, findings, rounds, not_testable, implausible)
    _gated(sel, model, opt, findings, rounds, not_testable, implausible)
    return findings, rounds, not_testable, implausible


def _gated(sel: Selector, model: Model, opt: Options, findings: list, rounds: list, not_testable: dict,
           implausible: dict) -> None:  # fmt: skip
    """The gated stage of :func:`_select` (terms present from some time on,
    :mod:`servo.diagnose.partial`) on ``model``, the vocabulary stage's; appends its
    findings and rounds.  Its candidates are counted among those of the round that ended
    the vocabulary's stage."""
    vocab = [r for r in rounds if not r.get("gated")]
    counted = len(vocab[-1]["scores"]) if vocab else 0
    for term, score, level, tstd in partial.rounds(sel, model, opt.alpha, counted, opt.max_findings - len(findings),
                                                   rounds, not_testable, implausible):  # fmt: skip
        findings.append(Finding(term, score, level, tstd))


def _regate(sel: Selector, base: Model, opt: Options, findings: list, unconfirmed: list, rounds: list,
            not_testable: dict, implausible: dict) -> bool:
    """When the held-out proof dropped a finding of the vocabulary stage (ungated), the
    gated stage, which ran on the model with it, is run again on the model the proof
    keeps (docs/diagnosis.md, 4a).  A drift and a term present from some time on both
    explain a change in time; the drift, tried first, stays only if the test part
    confirms it; if not, the gated stage is not left conditioned on it.  Replaces, in
    place, the gated findings and rounds (and their not-testable and implausible notes)
    by the new stage's; returns whether it ran."""
    if not any(partial.onset(f.term.params) is None and not f.sensor for f, _, _ in unconfirmed):
        return False
    kept = [f for f in findings if partial.onset(f.term.params) is None]
    findings[:] = kept
    rounds[:] = [r for r in rounds if not r.get("gated")]
    for d in (not_testable, implausible):
        for k in [k for k in d if k.endswith("(gated in time)")]:
            del d[k]
    model = base
    for f in kept:
        model = model.plus(f.term)
    _gated(sel, model, opt, findings, rounds, not_testable, implausible)
    return True


def _rounds(sel: Selector, model: Model, opt: Options, corrections: bool, findings, rounds, not_testable,
            implausible) -> Model:  # fmt: skip
    """The rounds of one stage of :func:`_select` (appending to its lists); returns the
    model with the stage's findings."""
    while len(findings) < opt.max_findings:
        cands, why = sel.eligible(model)
        cands = [c for c in cands if model.corrects(c) == corrections]
        if not cands:
            break
        sel.set_noise(model.refitted())
        label = "corrections of the model file" if corrections else "candidate terms"
        scores = [sel.score(model, c) for c in progress.each(cands, f"{label}, round {len(rounds) + 1}")]
        testable = [s for s in scores if s.S0 is not None]
        for s in scores:
            if s.S0 is None:
                not_testable[s.physics] = s.note
        # the breakaway test (intervals at rest) is one more candidate of a round that may
        # try stribeck_friction: it shares the round's family-wise level (run after the rounds)
        share = not corrections and breakaway_mod.applicable(model, cands)
        level = opt.alpha / max(len(testable) + share, 1)
        rounds.append({"level": level, "scores": testable, "breakaway_share": share})
        ok = sorted((s for s in testable if s.passes(level)), key=lambda s: s.delta_ic)
        added = False
        for best in ok:
            term, tstd = sel.refine(model, best.physics, best.thetas)
            trial = fit_model(sel.d, model.plus(term).refitted())
            why = VOCABULARY[best.physics].judging.implausible_on(trial.term_params(len(trial.model.terms) - 1), sel.d)
            if not why and _scope_of(sel.d, trial) and not _scope_of(sel.d, fit_model(sel.d, model.refitted())):
                # a term that takes the model's inertia away (a dead zone that scales a
                # two-level input down to nothing) is no physics; the next one is tried
                why = f"with it the model is out of scope: {_scope_of(sel.d, trial)}"
            if why:
                implausible[best.physics] = why
                continue
            findings.append(Finding(term, best, level, tstd))
            model = model.plus(term)
            added = True
            break
        if not added:
            break
    return model


def _scope_of(design: Design, fit: Fit) -> str:
    """Why the force balance of ``fit`` does not describe the recording ("" when it
    does; :func:`servo.diagnose.verdict.out_of_scope`)."""
    return verdict_mod.out_of_scope(fit.mass(None), fit.mass_std(), force_error_pct(design, fit, design.train_valid))


def _proven_models(base: Model, findings: list) -> list:
    """The models :func:`_sequence` fits, as given and refitted (whose rows the proof asks for)."""
    models = [base]
    for f in findings:
        if not f.sensor:
            models.append(models[-1].plus(f.term))
    return models + [m.refitted() for m in models]


def _sequence(design: Design, base: Model, findings: list) -> list:
    """Models baseline, +f1, +f1+f2, ... and their fits on the training part (a model
    file's terms as the file has them in the first, refitted once a finding is added:
    :meth:`Model.refitted`)."""
    models = [base]
    for f in findings:
        if not f.sensor:
            models.append(models[-1].plus(f.term))
    ts = [{} for _ in base.terms] + [f.theta_std for f in findings if not f.sensor]
    return [fit_model(design, m if i == 0 else m.refitted(), ts[: len(m.terms)]) for i, m in enumerate(models)]


def prepare(rec: Recording, settings: RobustSettings, opt: Options) -> Design:
    """Signals and the train/test split of ``rec`` on the path of ``settings``; refuses
    recordings with too few rows where the direction of motion is known."""
    sig = make_signals(rec, settings)
    m = sig.m
    train = np.arange(m) < int(round((1 - opt.test_fraction) * m))
    design = Design(sig, train)
    n_train = int(design.train_valid.sum())
    n_test = int((~train & sig.valid).sum())
    short = n_train < MIN_ROWS_PER_BLOCK * opt.blocks or n_test < MIN_ROWS_PER_BLOCK
    if short and sig.valid.mean() >= 0.5:  # the rows are usable, there are just too few of them
        raise OutOfDomain(
            f"recording too short to diagnose: {n_train} training and {n_test} test rows (decimation by "
            f"{settings.decimate}); need at least {MIN_ROWS_PER_BLOCK * opt.blocks} and {MIN_ROWS_PER_BLOCK}"
        )
    if (sig.valid.mean() < 0.2 and not dithered(sig)) or short:  # a dither's rows: band.dithered
        raise OutOfDomain(
            f"too few usable rows: {n_train} training and {n_test} test rows where the direction of motion is "
            f"known ({100 * sig.valid.mean():.0f} % of {m} rows; elsewhere the speed is within its noise, "
            f"{sig.v_threshold:.3g} m/s); record more motion or a longer recording"
        )
    return design


def _quantization(rec: Recording, opt: Options, base: Model, design: Design, H: int):
    """The lattice test and, if the sensor is quantised, the quantisation-aware path
    (:mod:`servo.diagnose.quantization`).  Returns ``(finding or None, design to use,
    lattice, note)``."""
    sig = design.sig
    lat = lattice_test(sig.x[design.train_samples])
    if not lat.found(opt.alpha):
        return None, design, lat, ""
    starts_tr = starts_in(design, design.train_rows, H)
    try:
        fit0 = fit_model(design, base)
        p0_tr = predict(design, fit0, starts_tr, H)
    except Unsimulable:
        return None, design, lat, "quantised sensor: the baseline cannot be simulated to judge a derivative path"
    blk = np.array_split(np.arange(starts_tr.size), opt.blocks)
    e0 = p0_tr.sse()[0]
    best = None
    paths = candidate_paths(sig.settings, 1.0 / sig.dt)
    for s in paths:
        try:
            d2 = prepare(rec, s, opt)
            baseline_mod.check_baseline(d2, base)
            f2 = fit_model(d2, base)
            e2 = predict(d2, f2, starts_tr, H).sse()[0]
        except (ServoError, Unsimulable):
            continue
        if best is None or e2.sum() < best[2].sum():
            best = (d2, f2, e2)
    level = opt.alpha / len(paths)
    if best is None:  # no narrower band leaves rows to fit: the quantum is still judged on the default rows
        best = (design, fit0, e0)
    d2, f2, e2 = best
    t, p = improvement_test(np.array([e0[b].sum() for b in blk]), np.array([e2[b].sum() for b in blk]))
    starts_te = starts_in(d2, ~d2.train_rows, H)  # the starts the rest of the proof uses
    p0_te = predict(design, fit0, starts_te, H)
    nr0, nr2 = p0_te.nrmse(), predict(d2, f2, starts_te, H).nrmse()
    s2 = d2.sig.settings
    q = Finding(Term.make(LATTICE, {"step": lat.step}), None, level, {}, lat, (t, p), prediction=p0_te)
    q.params = {"step": lat.step, "offset": lat.offset, "noise_share": min(lat.step**2 / 12 / max(sig.noise_x**2, 1e-300), 1.0),
                "decimate": float(s2.decimate), "cutoff_hz": s2.cutoff(1.0 / sig.dt)}  # fmt: skip
    q.before = {"force_rel_pct": force_error_pct(design, fit0, ~design.train_rows & sig.valid), "output_nrmse": nr0}
    q.after = {"force_rel_pct": force_error_pct(d2, f2, ~d2.train_rows & d2.sig.valid), "output_nrmse": nr2,
               "rows_differ": True}  # fmt: skip
    q.where = {"text": f"every sample: positions on a {lat.step:.3g} m lattice ({100 * lat.fraction:.0f} % of samples); "
                       f"the rows now stop at {0.4 / d2.sig.row_dt:.3g} Hz (decimation by {s2.decimate})"}  # fmt: skip
    if p < level and nr2 < nr0:
        return q, d2, lat, ""
    return _quantum_on_default_rows(design, fit0, lat, level, q)


def _quantum_on_default_rows(design: Design, fit0: Fit, lat: Lattice, level: float, q: Finding):
    """A quantum that no narrower band predicts better, named on the default rows where
    its noise is a share of the held-out error that matters
    (:mod:`servo.diagnose.quantization`): the test part's positions on the training
    part's lattice, and the quantum's white noise at least ``SHARE_MIN`` of the
    baseline's RMS residual on the test rows.  Returns :func:`_quantization`'s tuple."""
    sig = design.sig
    nope = f"quantised sensor (step {lat.step:.3g} m) but a narrower band does not predict better"
    frac_te, p_te = heldout_on_lattice(sig.x[~design.train_samples], lat)
    test = ~design.train_rows & sig.valid
    # the quantum's noise attenuates the inertia fitted on the acceleration rows it is in
    s_acc = acceleration_share(lat.step, sig.rows(sig.af)[design.train_valid], sig.settings, 1.0 / sig.dt)
    J = attenuated_inertia(fit0.mass(), s_acc)
    rms = float(np.sqrt(np.mean(fit0.residual[test] ** 2))) if test.any() else 0.0
    floor_q = quantum_floor(lat.step, J, sig.settings, 1.0 / sig.dt)
    share = error_share(floor_q, rms)
    q.quant_heldout = {"heldout_fraction_on_lattice": frac_te, "heldout_lattice_p": p_te, "quantum_floor": floor_q,
                       "heldout_rms": rms, "share_of_heldout_rms": share, "acceleration_share": s_acc}  # fmt: skip
    if not (p_te < level and frac_te >= MIN_FRACTION and share >= SHARE_MIN):
        return None, design, lat, f"{nope}, and its noise makes {100 * share:.0f} % of the held-out residual"
    s = sig.settings
    q.params.update(decimate=float(s.decimate), cutoff_hz=s.cutoff(1.0 / sig.dt), share_of_heldout_rms=share)
    q.after = {**q.before, "rows_differ": False}
    q.prediction = None
    q.where = {"text": f"every sample: positions on a {lat.step:.3g} m lattice ({100 * lat.fraction:.0f} % of the "
                       f"training samples, {100 * frac_te:.0f} % of the held-out ones); its noise makes "
                       f"{100 * share:.0f} % of the baseline's held-out residual; the rows stay (a narrower band "
                       "does not predict better)"}  # fmt: skip
    return q, design, lat, ""


def _gain(r0: np.ndarray, r1: np.ndarray, rows: np.ndarray) -> float:
    """The share of the held-out residual RMS on ``rows`` a term removes: ``1 -
    rms(r1)/rms(r0)`` (negative when it adds)."""
    return float(1.0 - np.linalg.norm(r1[rows]) / max(np.linalg.norm(r0[rows]), 1e-300))


def material_share(r0: np.ndarray, r1: np.ndarray, rows: np.ndarray, floor: float) -> float:
    """The share of the held-out residual in excess of the noise floor that a term
    removes: ``(rms(r0) - rms(r1)) / max(rms(r0) - floor, EFFECT * floor)`` over ``rows``
    (force unit for ``floor``, the residual RMS position noise alone gives).  The excess is
    counted as at least :data:`EFFECT` of the floor: a model already within the
    proving ground's effect size of its floor leaves nothing a finding could be material
    against, and a gain of a hundredth of the floor on a long recording is not physics.
    Without a finite positive floor the share is infinite (the rule does not judge)."""
    if not (math.isfinite(floor) and floor > 0):  # no floor to measure against (an unfittable mass): not judged
        return math.inf
    n = max(int(np.count_nonzero(rows)), 1)
    a, b = (float(np.linalg.norm(r[rows])) / math.sqrt(n) for r in (r0, r1))
    return (a - b) / max(a - floor, EFFECT * floor, 1e-300)


def _proven(design: Design, fit: Fit, test_rows: np.ndarray) -> np.ndarray:
    """``fit``'s held-out residual (m,) as the proof reads it: each term's
    :meth:`~servo.physics.base.Judging.proven` (a drift's course cross-fitted on the test
    part; the prediction for every other term)."""
    r = fit.residual
    for t in fit.model.terms:
        r = VOCABULARY[t.physics].judging.proven(design, t.params, r, test_rows)
    return r


def _same_effect(design: Design, base: Model, findings: list, cols: list, i: int, why: str, test_rows: np.ndarray,
                 noise_x: float | None) -> tuple[int, str]:  # fmt: skip
    """Which of two names of one effect the proof drops, when ``cols[i - 1]`` is not
    material after the earlier findings: an earlier ``cols[j - 1]`` that is not material
    once ``cols[i - 1]`` is in the model (the findings up to it, ``cols[j - 1]`` moved
    last), while ``cols[i - 1]`` is material without it and the model without it
    predicts the test part better than the model without ``cols[i - 1]``, was the weaker
    description of the part they share (a LuGre element's bristles read as a Stribeck dip
    before its Dahl loop): it is dropped instead.  Returns the index into the fits of
    the finding to drop and the reason."""
    if i < 2:  # the first finding: no earlier name of the same effect
        return i, why
    upto = findings[: findings.index(cols[i - 1]) + 1]

    def tail(fs):  # the last two fits' held-out residuals, and the floor of the one before
        fits = _sequence(design, base, fs)
        r = [_proven(design, f, test_rows) for f in fits[-2:]]
        return r[0], r[1], verdict_mod.force_floor(design.sig, fits[-2].mass(), noise_x)

    n = max(int(np.count_nonzero(test_rows)), 1)
    rms = lambda r: float(np.linalg.norm(r[test_rows])) / math.sqrt(n)  # noqa: E731
    r_no_i = tail(upto[:-1])[1]
    for j in range(1, i):
        other = cols[j - 1]
        r_no_j, r_all, floor = tail([f for f in upto if f is not other] + [other])
        share = material_share(r_no_j, r_all, test_rows, floor)
        a0, a1, fl = tail([f for f in upto if f is not other])  # cols[i - 1] without cols[j - 1]
        alone = material_share(a0, a1, test_rows, fl)
        if share < SHARE and alone >= SHARE and rms(r_no_j) < rms(r_no_i):
            other.heldout = {**(other.heldout or {}), "share": share}
            return j, (f"not material beside {cols[i - 1].physics}, which describes the same part of the residual "
                       f"better: after it, this term removes {100 * share:.2g} % of the held-out residual above the "
                       f"noise floor, less than {100 * SHARE:.0f} %")  # fmt: skip
    return i, why


def output_worse(before: Prediction, after: Prediction, alpha: float = ALPHA) -> bool:
    """Whether a finding's rise of the short-horizon output error (the caller has seen
    the NRMSE rise by more than :data:`OUTPUT_TOLERANCE`) is the model's, not one
    stretch's: the starts (in time order) cut into up to :data:`HELDOUT_BLOCKS`
    contiguous blocks of at least 4; the rise counts where it is consistent over them
    (the sign-flip test, :func:`~servo.diagnose.select.signflip_test`, that the blocks'
    squared prediction errors drop from ``after`` to ``before`` at ``alpha``) or where
    the NRMSE still rises by more than the tolerance without the block that rises most.
    At the noise floor the NRMSE is a ratio of sums a few starts dominate (a step's
    edge where the state estimate is off): on an open-loop step recording behind a
    sensor low-pass the right lag (fitted 510 Hz for 500) raised it by 10 %, all of it
    from one start of 75 (a paired t of 0.43), and the lag was dropped while the
    baseline was called ``consistent`` (issue 24).  A lag or a saturation whose
    simulated output runs away from many starts (2.3 x on a closed-loop step
    recording, the sign-flip test not significant over its mixed blocks) still counts.
    With fewer than 4 blocks the NRMSE's rise alone counts."""
    e0, e1 = before.sse()[0], after.sse()[0]
    n = min(HELDOUT_BLOCKS, e0.size // 4)
    if n < 4:
        return True
    parts = np.array_split(np.arange(e0.size), n)
    S0 = np.array([float(e0[p].sum()) for p in parts])
    S1 = np.array([float(e1[p].sum()) for p in parts])
    if signflip_test(S1, S0)[1] <= alpha:
        return True
    k = int(np.argmax(S1 - S0))  # the block that rises most
    rest0, rest1 = float(S0.sum() - S0[k]), float(S1.sum() - S1[k])
    return rest1 > rest0 * (1 + OUTPUT_TOLERANCE) ** 2


def _prove(design: Design, base: Model, findings: list, test_rows: np.ndarray, starts: np.ndarray, H: int,
           alpha: float = ALPHA, noise_x: float | None = None):  # fmt: skip
    """Sequential fits and held-out errors; drops findings that do not lower the test
    part's force error or that raise its simulated-output NRMSE by more than
    :data:`OUTPUT_TOLERANCE`; a finding beside the first must also earn its place on
    the test part with the earlier ones in the model (:func:`heldout_signflip` at
    ``alpha`` over the findings beyond the first: one name per effect), and no finding
    keeps parameters its physics refuses in the final model (``implausible``); every
    finding must remove :data:`SHARE` of the held-out residual the model before it
    leaves above the noise floor of a position noise of std ``noise_x`` (m; default the
    rows' estimate, :func:`material_share`), or it is listed as not material with its
    share.  Each kept finding carries its held-out ``p`` and ``share``
    (``Finding.heldout``).  Returns fits, force
    errors, NRMSEs, predictions, the unconfirmed findings and a note if the model cannot
    be simulated."""
    unconfirmed = []
    y0 = design.target_raw(Model())
    norm0 = max(float(np.linalg.norm(y0[test_rows])), 1e-300)
    while True:
        fits = _sequence(design, base, findings)
        res = [_proven(design, f, test_rows) for f in fits]
        errs = [float(100 * np.linalg.norm(r[test_rows]) / norm0) for r in res]
        preds, note = [], ""
        for f in fits:
            try:
                preds.append(predict(design, f, starts, H))
            except Unsimulable as exc:
                preds.append(None)
                note = str(exc)
        nr = [p.nrmse() if p is not None else None for p in preds]
        cols = [f for f in findings if not f.sensor]  # fits[i + 1] adds cols[i]
        level = alpha / max(len(cols) - 1, 1)
        final = fits[-1]
        bad, why = None, ""
        for i in range(1, len(fits)):
            # the short-horizon simulation has no clock: a term whose course no past
            # forecasts (a drift) is judged on its cross-fitted force error instead
            clock = bool(VOCABULARY[cols[i - 1].physics].judging.follows)
            # and it carries a term through its effect's [drive] fields: a term whose effect
            # has none (columns alone, as a feature library's) is not judged by it
            simulated = bool(EFFECTS[cols[i - 1].physics].drive)
            worse_out = (nr[i] is not None and nr[i - 1] is not None and nr[i] > nr[i - 1] * (1 + OUTPUT_TOLERANCE)
                         and not clock and simulated and output_worse(preds[i - 1], preds[i], alpha))  # fmt: skip
            t, p, nb = heldout_signflip(res[i - 1], res[i], test_rows)
            floor = verdict_mod.force_floor(design.sig, fits[i - 1].mass(), noise_x)
            share = material_share(res[i - 1], res[i], test_rows, floor)
            cols[i - 1].heldout = {"p": p, "t": t, "blocks": nb, "level": level if i > 1 else None,
                                   "share": share if math.isfinite(share) else None}  # None: no floor to judge by
            unphysical = VOCABULARY[cols[i - 1].physics].judging.implausible_on(final.term_params(len(base.terms) + i - 1), design)
            if not errs[i] < errs[i - 1] or worse_out:
                bad = i
                break
            if clock and _gain(res[i - 1], res[i], test_rows) < MATERIAL:
                # fitted on half the test part, judged on the rest: it must remove a
                # material share (a switched-on force is followed a little too)
                bad, why = i, (f"its course cross-fitted on the held-out part removes "
                               f"{100 * _gain(res[i - 1], res[i], test_rows):.0f} % of the residual RMS there, "
                               f"less than {100 * MATERIAL:.0f} %")  # fmt: skip
                break
            if not share >= SHARE:
                bad, why = i, (f"not material: it removes {100 * share:.2g} % of the held-out residual the model "
                               f"before it leaves above the noise floor ({floor:.3g} RMS), less than "
                               f"{100 * SHARE:.0f} %")  # fmt: skip
                bad, why = _same_effect(design, base, findings, cols, bad, why, test_rows, noise_x)
                break
            if i > 1 and not p <= level:
                bad, why = i, (f"a further finding that did not earn its place on the held-out part with the earlier "
                               f"ones in the model: its gain there has a {100 * p:.2g} % chance of being spurious "
                               f"(sign-flip test over {nb} blocks, level {100 * level:.2g} %)")  # fmt: skip
                break
            if unphysical:
                bad, why = i, f"unphysical in the final model: {unphysical}"
                break
        if bad is None:
            return fits, errs, nr, preds, unconfirmed, note
        f = cols[bad - 1]
        findings.remove(f)
        f.why = why
        k = len(fits[bad].model.terms) - 1  # the dropped term, as fitted when it was tried
        f.params, f.std = fits[bad].term_params(k), fits[bad].term_std(k)
        unconfirmed.append((f, {"force_rel_pct": errs[bad - 1], "output_nrmse": nr[bad - 1]},
                            {"force_rel_pct": errs[bad], "output_nrmse": nr[bad]}))  # fmt: skip


def _breakaway(design: Design, fit: Fit, rounds: list, errs: list, nr: list, opt: Options, step: float = 0.0,
               not_testable: dict | None = None):  # fmt: skip
    """The breakaway test (:mod:`servo.diagnose.breakaway`) on the final model of the rows,
    at the level of the last round that shared its family-wise level with it (the round on
    that model); ``step`` a quantised sensor's lattice step (0: none).  Returns
    ``(finding, unconfirmed entry)``, either None."""
    shared = [r["level"] for r in rounds if r.get("breakaway_share")]
    if not shared or not all(map(fit.model.has, VOCABULARY[BREAKAWAY].search.requires)) or fit.model.has(BREAKAWAY):
        return None, None
    if _scope_of(design, fit):
        return None, None
    hidden = [VOCABULARY[t.physics].judging.rests for t in fit.model.terms if VOCABULARY[t.physics].judging.rests]
    if hidden:  # the rests are another term's (a play's dwells): they test no breakaway
        if not_testable is not None:
            not_testable[f"{BREAKAWAY} (breakaway at rest)"] = hidden[0]
        return None, None
    level = shared[-1]
    res = breakaway_mod.test(design, fit, step)
    if not res.testable and not_testable is not None:  # say why it could not be tested
        not_testable[f"{BREAKAWAY} (breakaway at rest)"] = res.note
    if not res.passes(level):
        return None, None
    alt = res.split  # the held-out part holds too few intervals at rest: proven on training events held out from the fit
    held = res  # the held-out part's own result, said beside the split's
    if not res.confirmed(opt.alpha) and alt is not None and alt.passes(level) and alt.confirmed(opt.alpha):
        res = alt
    vs = float(design.sig.v_threshold)
    term = Term.make(BREAKAWAY, {"stribeck_velocity": vs}, (res.Fs - res.Fc,))
    ev = {**res.evidence(), "level": level}
    f = Finding(term, None, level, {}, breakaway=ev)
    f.params = {"dFs": res.Fs - res.Fc, "stribeck_velocity": vs, "Fs": res.Fs}
    f.std = {"dFs": float(np.hypot(res.Fs_std, res.Fc_std)), "Fs": res.Fs_std}
    before = {"force_rel_pct": errs[-1], "output_nrmse": nr[-1], "held_excess_rms": res.excess_before}
    after = {"force_rel_pct": errs[-1], "output_nrmse": nr[-1], "held_excess_rms": res.excess_after}
    f.before, f.after = before, after
    if res.proof == "held-out part":
        counts = f"{res.k} of {res.n} training and {res.k_test} of {res.n_test} held-out intervals"
    else:  # the held-out part holds too few intervals at rest: proven on training events the fit did not use
        own = (f"; {held.k_test} of its {held.n_test} events beyond the bound, p {held.p_test:.3g}" if held.n_test
               else "")  # fmt: skip
        counts = (f"the held-out part holds {res.n_rest_test} intervals at rest (fewer than "
                  f"{breakaway_mod.MIN_REST_TEST}{own}), so it cannot test a breakaway on its own; {res.k} of {res.n} "
                  f"training intervals (every other one) and {res.k_test} of {res.n_test} training intervals held out "
                  f"from that test and fit")  # fmt: skip
    f.where = {"text": f"at rest: {counts} at rest or reversing hold forces beyond the sliding level and their local "
                       f"noise (p <= {breakaway_mod.TAU:g} each; combined p {res.p:.3g}, proof {res.p_test:.3g}; "
                       f"typical bound {res.bound:.3g}, Fc {res.Fc:.3g}); breakaway Fs {res.Fs:.3g} (proof {res.Fs_test:.3g})"}  # fmt: skip
    if res.confirmed(opt.alpha):
        return f, None
    ev["reason"] = (f"the held-out part's intervals at rest do not hold forces beyond the sliding level "
                    f"({res.k_test} of {res.n_test}, p {res.p_test:.3g} against {opt.alpha:g})")  # fmt: skip
    if alt is not None:  # say that the held-out part could not test it, and what the split gave
        ev["reason"] = (f"not proven: the held-out part holds {res.n_rest_test} intervals at rest (fewer than "
                        f"{breakaway_mod.MIN_REST_TEST}), so it cannot test a breakaway on its own "
                        f"({res.k_test} of {res.n_test} of its events beyond the bound), and the training events "
                        f"held out from the fit do not confirm it ({alt.k} of {alt.n} fitted, p {alt.p:.3g} against "
                        f"{level:.3g}; {alt.k_test} of {alt.n_test} held out, p {alt.p_test:.3g} against {opt.alpha:g})")  # fmt: skip
    return None, (f, before, after)


def _mode_support(design, base, findings, fits, errs, nr, preds, unconfirmed, note, test_rows, starts, H, alpha,
                  instrument):  # fmt: skip
    """The modes the rows named (``resonance`` findings of the selection), each held
    against the recording's own frequency response (:func:`servo.diagnose.frf_modes.support`):
    a mode the response does not show is dropped, listed under ``unconfirmed`` with the
    reason, and the rest proven again without it.  Returns the proof's lists as
    :func:`_prove` does, with the findings kept first."""
    verdicts = {i: (ok, ev) for i, ok, ev in frf_modes.support(design, fits[-1], alpha, instrument)}
    drop = []
    for k, f in enumerate(findings):
        i = len(fits[k + 1].model.terms) - 1
        if f.physics == FRF and i in verdicts:
            ok, ev = verdicts[i]
            f.frf_support = ev
            if not ok:
                drop.append((f, ev, {"force_rel_pct": errs[k], "output_nrmse": nr[k]},
                             {"force_rel_pct": errs[k + 1], "output_nrmse": nr[k + 1]}))  # fmt: skip
    if not drop:
        return findings, fits, errs, nr, preds, unconfirmed, note
    kept = [f for f in findings if all(f is not d[0] for d in drop)]
    fits, errs, nr, preds, more, note = _prove(design, base, kept, test_rows, starts, H, alpha)
    for f, ev, before, after in drop:
        f.frf = ev  # its evidence and the reason (the report's unconfirmed entry reads it)
        unconfirmed.append((f, before, after))
    return kept, fits, errs, nr, preds, unconfirmed + more, note


def _input_path(design, base, findings, fits, errs, nr, preds, unconfirmed, note, test_rows, starts, H, alpha,
                instrument=None):  # fmt: skip
    """The input-path term the rows named (a delay or a sensor lag) held against the
    recording's own frequency response (:func:`servo.diagnose.frf_modes.input_path`):
    where the response prefers the other, that term stands in its place (its parameter
    from the response), the findings are proven again, and the finding carries the
    evidence (``Finding.frf_path``)."""
    swap = frf_modes.input_path(design, fits[-1], alpha, instrument)
    if swap is None:
        return findings, fits, errs, nr, preds, unconfirmed, note
    for f in findings:
        if f.physics == swap["named"]:
            f.term = Term.make(swap["physics"], swap["theta"])
            f.theta_std = {}
            f.frf_path = swap["evidence"]
    fits, errs, nr, preds, more, note = _prove(design, base, findings, test_rows, starts, H, alpha)
    return findings, fits, errs, nr, preds, unconfirmed + more, note


def _frf_modes(design: Design, fits: list, errs: list, nr: list, preds: list, starts: np.ndarray, H: int,
               alpha: float, instrument: np.ndarray | None = None):  # fmt: skip
    """The frequency-domain path (:mod:`servo.diagnose.frf_modes`) on the final model of
    the rows; each mode it proves on the test part's own response is added to the model
    as a ``resonance`` term with its gain held (the rows, below the mode, cannot fit it).
    Its proof is the held-out response alone: the force rows do not reach the mode, and
    the short-horizon output is not a test of it either (with the generator's own mode,
    1.4 kHz on a 20 kHz open-loop chirp, the output NRMSE rose from 0.00085 to 0.00091,
    the rows' force error from 0.064 to 0.068 %); both are reported.  Appends to
    ``fits``, ``errs``, ``nr``, ``preds``; returns ``(result, findings, terms,
    unconfirmed)``.  ``instrument``: the recording's ``r``, if any (step 6 of that
    module)."""
    found, terms, dropped = [], [], []
    scope = _scope_of(design, fits[-1])
    if scope:
        res = frf_modes.Result(band_hz=[], note=f"not run: the recording is out of scope ({scope})")
        return res, found, terms, dropped
    res = frf_modes.run(design, fits[-1], alpha, instrument)
    test_rows = ~design.train_rows & design.sig.valid
    for m in list(res.modes):
        p = m.params
        term = Term.make(FRF, {"frequency_hz": p["frequency_hz"], "zeta": p["zeta"]}, (p["gain"],))
        fit = fit_model(design, fits[-1].model.plus(term), fits[-1].theta_std)
        k = len(fit.model.terms) - 1
        fit.std[k] = (m.std.get("gain", 0.0),)
        fit.theta_std[k] = {n: m.std[n] for n in ("frequency_hz", "zeta") if n in m.std}
        try:
            pred = predict(design, fit, starts, H)
            nrk = pred.nrmse()
        except Unsimulable:
            pred, nrk = None, None
        err = force_error_pct(design, fit, test_rows)
        ev = m.evidence
        before = {"force_rel_pct": errs[-1], "output_nrmse": nr[-1], "frf_sse": ev["test_sse_before"]}
        after = {"force_rel_pct": err, "output_nrmse": nrk, "frf_sse": ev["test_sse_after"]}
        f = Finding(term, None, alpha, fit.theta_std[k], before=before, after=after, params=fit.term_params(k),
                    std=fit.term_std(k), frf=ev)  # fmt: skip
        bw = res.band_hz
        side = "above" if p["frequency_hz"] > res.rows_edge_hz else "within"
        f.where = {"frequency": {"peak_hz": p["frequency_hz"], "band_hz": bw},
                   "text": f"a mode at {p['frequency_hz']:.4g} Hz, {side} the rows' band (found on the frequency response "
                           f"at full rate, {bw[0]:.4g}-{bw[1]:.4g} Hz)"}  # fmt: skip
        fits.append(fit)
        errs.append(err)
        nr.append(nrk)
        preds.append(pred)
        found.append(f)
        terms.append(term)
    for m in res.dropped:  # dropped by the held-out H1: reported with their parameters
        term = Term.make(FRF, {"frequency_hz": m.params["frequency_hz"], "zeta": m.params["zeta"]},
                         (m.params["gain"],))  # fmt: skip
        ev = m.evidence
        before = {"force_rel_pct": errs[-1], "output_nrmse": nr[-1], "frf_sse": ev.get("test_sse_before")}
        f = Finding(term, None, alpha, {}, params=dict(m.params), std=dict(m.std), frf={**ev, "reason": m.reason})
        dropped.append((f, before, {**before, "frf_sse": ev.get("test_sse_after")}))
    return res, found, terms, dropped


#: BLAS threads while a diagnosis runs: its products are a few columns wide, where
#: OpenBLAS's threads cost more than they give and, spinning while they wait, slow down
#: beside other processes (the 1 000 000-sample benchmark: 5.3 s on one thread against
#: 7.2 s on two with another job on the machine; docs/studies/2026-11-23-diagnose-speed.md)
BLAS_THREADS = 1


def diagnose(rec: Recording, opt: Options | None = None) -> Diagnosis | Unscoped:
    """Diagnose ``rec`` (see module doc).  A recording outside the domain (an output
    that does not move, too few usable rows: :mod:`servo.diagnose.scope`) gets an
    :class:`~servo.diagnose.scope.Unscoped` diagnosis, verdict ``out_of_scope`` with the
    measured reason.  Raises a one-line :class:`~servo.errors.ServoError` for options or
    a model that cannot be used.  BLAS runs on :data:`BLAS_THREADS` threads meanwhile, as
    it did before once it returns.  The limit is the process's: diagnoses run side by
    side in threads of one process would reset each other's; the study and the fleet run
    them in worker processes."""
    with threadpool_limits(limits=BLAS_THREADS, user_api="blas"):
        try:
            return _diagnose(rec, opt)
        except OutOfDomain as exc:
            return Unscoped(rec, opt or Options(), str(exc))


def _diagnose(rec: Recording, opt: Options | None) -> Diagnosis:
    opt = opt or Options()
    if not 0.05 <= opt.test_fraction <= 0.5:
        raise IdentificationError(f"test fraction {opt.test_fraction:g} must lie between 0.05 and 0.5")
    if opt.blocks < 4:
        raise IdentificationError(f"at least 4 cross-validation blocks are needed, got {opt.blocks}")
    held_out_s = rec.n * rec.dt * opt.test_fraction
    if opt.horizon_s is not None and not opt.horizon_s < held_out_s:  # (its samples are allocated per start)
        raise IdentificationError(f"horizon {opt.horizon_s:g} s is not shorter than the held-out part of the recording "
                                  f"({held_out_s:.3g} s): no simulated output of that length fits in it")  # fmt: skip
    check_memory(rec.n, opt)
    base = baseline_mod.from_file(opt.model) if opt.model else baseline_mod.from_terms(opt.baseline)
    check_recording(rec)  # after the options and the model: those are refused whatever the data
    progress.stage("signals and the baseline fit")
    design0, band_note = choose_band(rec, opt, prepare)
    check_memory(rec.n, replace(opt, settings=design0.sig.settings))
    baseline_mod.check_baseline(design0, base)
    base = baseline_mod.without_idle_inputs(base, design0.sig.u)
    H = horizon_samples(design0, opt.horizon_s)

    qfind, design, lattice, qnote = _quantization(rec, opt, base, design0, H)
    del design0  # a quantised sensor's other path: the first design's signals and rows not kept beside it
    sig = design.sig
    test_rows = ~design.train_rows & sig.valid
    blocks = make_blocks(design.train_valid, opt.blocks)
    sel = Selector(design, blocks, opt.alpha)
    findings, rounds, not_testable, implausible = _select(sel, base, opt)
    design.forget(keep=_proven_models(base, findings))  # the variants' rows: not asked for again


    progress.stage("held-out proof")
    starts_test = starts_in(design, ~design.train_rows, H)
    fits, errs, nr, preds, unconfirmed, note = _prove(design, base, findings, test_rows, starts_test, H, opt.alpha)
    if _regate(sel, base, opt, findings, unconfirmed, rounds, not_testable, implausible):
        # the gated stage on the model the proof kept; its findings proven as the others
        dropped = [e for e in unconfirmed if partial.onset(e[0].term.params) is None]  # not the old gated ones
        fits, errs, nr, preds, unconfirmed, note = _prove(design, base, findings, test_rows, starts_test, H, opt.alpha)
        unconfirmed = dropped + unconfirmed
    if findings and _scope_of(design, fits[-1]):
        # a recording the force balance does not describe: its findings fit noise (an
        # unrelated position got several); none is named
        why = _scope_of(design, fits[-1])
        implausible.update({f.physics: f"the recording is out of scope: {why}" for f in findings})
        findings = []
        fits, errs, nr, preds, unconfirmed, note = _prove(design, base, findings, test_rows, starts_test, H, opt.alpha)
    if any(f.physics == FRF for f in findings):  # a mode the rows named needs the frequency response's support
        findings, fits, errs, nr, preds, unconfirmed, note = _mode_support(design, base, findings, fits, errs, nr, preds,
                                                                           unconfirmed, note, test_rows, starts_test,
                                                                           H, opt.alpha, rec.r)  # fmt: skip
    if findings and not _scope_of(design, fits[-1]):  # a delay or a lag: the frequency response tells which
        findings, fits, errs, nr, preds, unconfirmed, note = _input_path(design, base, findings, fits, errs, nr, preds,
                                                                         unconfirmed, note, test_rows, starts_test, H,
                                                                         opt.alpha, rec.r)  # fmt: skip
    variables = state_variables(sig, opt.position_unit)
    # a named quantum is sensor noise too: q^2/12 wherever the arm moves across steps
    # (the rows' estimate misses it where the arm rests on one step most of the time)
    noise_x = max(sig.noise_x, qfind.params["step"] / math.sqrt(12.0)) if qfind is not None else None

    def checks(fit, r, nrmse):
        w = design.train_valid
        first, last = np.flatnonzero(w)[[0, -1]]
        tau_r = integrated_time(np.where(w, r, 0.0)[first : last + 1])
        J = fit.mass()
        return verdict_mod.assess(design, r, J, tau_r, variables, opt.alpha, nrmse, noise_x,
                                  verdict_mod.estimation_error(design, fit))  # fmt: skip

    if findings and not checks(fits[0], heldout_residual(design, base, blocks, test_rows), nr[0])["failed"]:
        # the baseline explains the recording to its noise: a term is named only where it
        # removes a material share of the held-out residual (a 9 % gain from a delay on
        # a seek null was read as physics); the others are listed with their gain
        small = []
        for i, f in enumerate(findings):
            g = _gain(fits[i].residual, fits[i + 1].residual, test_rows)
            if g < MATERIAL:
                k = len(fits[i + 1].model.terms) - 1
                f.params, f.std = fits[i + 1].term_params(k), fits[i + 1].term_std(k)
                f.why = (f"the baseline already explains the recording to its noise (every check passed); this term "
                         f"removes {100 * g:.0f} % of the held-out residual RMS, less than {100 * MATERIAL:.0f} %")  # fmt: skip
                small.append((f, {"force_rel_pct": errs[i], "output_nrmse": nr[i]},
                              {"force_rel_pct": errs[i + 1], "output_nrmse": nr[i + 1]}))  # fmt: skip
        if small:
            findings = [f for f in findings if f not in [e[0] for e in small]]
            fits, errs, nr, preds, dropped, note = _prove(design, base, findings, test_rows, starts_test, H, opt.alpha)
            unconfirmed = unconfirmed + dropped + small
    if qfind is not None and not qfind.after.get("rows_differ"):  # named on these rows: errors unchanged by it
        qfind.before = {"force_rel_pct": errs[0], "output_nrmse": nr[0]}
        qfind.after = {**qfind.before, "rows_differ": False}
    for i, f in enumerate(findings):
        f.before = {"force_rel_pct": errs[i], "output_nrmse": nr[i]}
        f.after = {"force_rel_pct": errs[i + 1], "output_nrmse": nr[i + 1]}
        k = len(fits[i + 1].model.terms) - 1
        f.params, f.std = fits[i + 1].term_params(k), fits[i + 1].term_std(k)
    step = lattice.step if lattice.found(opt.alpha) else 0.0  # a quantised sensor's pulses near rest
    bfind, bdrop = _breakaway(design, fits[-1], rounds, errs, nr, opt, step, not_testable)
    if bdrop is not None:
        unconfirmed.append(bdrop)
    progress.stage("the frequency response above the rows' band")
    frf, frf_found, frf_terms, frf_dropped = _frf_modes(design, fits, errs, nr, preds, starts_test, H, opt.alpha, rec.r)
    findings += frf_found
    unconfirmed += frf_dropped
    final = fits[-1]

    progress.stage("locate tests and the verdict")  # on the baseline's held-out residual
    r_before = heldout_residual(design, base, blocks, test_rows)
    r_after = heldout_residual(design, final.model, blocks, test_rows)
    follows = []  # terms whose course through the test part the verdict's residual fits there (a drift)
    for t in final.model.terms:
        phys = VOCABULARY[t.physics]
        if phys.judging.follows:
            r_after = phys.judging.followed(design, t.params, r_after, test_rows)
            follows.append(phys.judging.follows)
    sel.set_noise(base)
    tau = sel.tau
    y0 = design.target_raw(Model())
    r0 = np.where(sig.valid, r_before, 0.0)
    fs = 1.0 / sig.row_dt
    loc = {
        "time": locate.window_test(sig.t_rows, r_before, sig.valid, tau, opt.alpha),
        "state": locate.state_test(r_before, sig.valid, tau, variables, opt.alpha),
        "spectrum": locate.spectrum_test(r0, fs, opt.alpha),
        "coherence": locate.coherence_test(r0, y0, fs, opt.alpha),
        "xcorr": locate.xcorr_test(r0, y0, sig.row_dt, opt.alpha),
        "tau": tau,
    }
    for i, f in enumerate(findings):
        if f.frf is None and f.breakaway is None:
            f.where = locate.where(fits[i].residual - fits[i + 1].residual, sig.valid, sig.t_rows, variables, fs)
            if partial.onset(f.term.params) is not None:  # a term gated in time says so first
                f.where["from_s"] = partial.onset(f.term.params)
                f.where["text"] = f"present from t = {f.where['from_s']:.4g} s on (absent before); " + f.where["text"]
    if qfind is not None:
        findings.insert(0, qfind)
    if bfind is not None:  # not a column of the rows: after the findings it does not change
        findings.append(bfind)

    base_checks, final_checks = checks(fits[0], r_before, nr[0]), checks(final, r_after, nr[-1])
    verdict_mod.add_frf(base_checks, frf.before, frf)
    verdict_mod.add_frf(final_checks, frf.after, frf)
    scope = verdict_mod.out_of_scope(final.mass(None), final.mass_std(),
                                     force_error_pct(design, final, design.train_valid))
    J_fin, J_sd = final.mass(None), final.mass_std()
    if scope and qfind is not None and (J_fin is None or not J_fin > verdict_mod.J_SIGMAS * (J_sd or 0.0)):
        # an inertia the quantum's noise leaves unresolved: the quantum's reason, not "not a mass"
        s_acc = acceleration_share(qfind.params["step"], sig.rows(sig.af)[design.train_valid], sig.settings, 1.0 / sig.dt)
        scope = scope_reason(qfind.params["step"], s_acc, J_fin, J_sd) or scope
    sensor = ""
    if qfind is not None and qfind.quant_heldout is not None and len(findings) == 1:  # the quantum alone, on these rows
        sensor = (f"of which the position sensor's quantum ({qfind.params['step']:.3g} m) makes "
                  f"{100 * qfind.params['share_of_heldout_rms']:.0f} % (named from the lattice the held-out positions "
                  "lie on; a narrower band does not predict better)")  # fmt: skip
    verdict = verdict_mod.decide(base_checks, final_checks, len(findings), scope, opt.force_unit,
                                 tuple(f"breakaway ({f.physics}, proven on the {f.breakaway['proof']})" for f in findings
                                       if f.breakaway is not None), sensor)  # fmt: skip
    if follows and verdict["verdict"] != "out_of_scope":
        verdict["text"] += f" (in the final model's held-out residual, {'; '.join(follows)})"
    verdict.update(baseline_checks=base_checks, final_checks=final_checks)

    base_err = {"force_rel_pct": errs[0], "output_nrmse": nr[0]}
    if qfind is not None and qfind.after.get("rows_differ"):
        base_err = qfind.before
    errors = {
        "train_force_rel_pct": {"before": force_error_pct(design, fits[0], design.train_valid),
                                "after": force_error_pct(design, final, design.train_valid)},
        "test_force_rel_pct": {"before": base_err["force_rel_pct"], "after": errs[-1]},
        "test_output_nrmse": {"before": base_err["output_nrmse"], "after": nr[-1]},
        "horizon_s": H * sig.dt,
    }  # fmt: skip
    return Diagnosis(
        rec=rec, opt=opt, sig=sig, design=design, baseline=base, baseline_fit=fits[0], final_fit=final,
        findings=findings, unconfirmed=unconfirmed, rounds=rounds, not_testable=not_testable, implausible=implausible,
        residual_before=r_before, residual_after=r_after, test_rows=test_rows, locate=loc, state=variables,
        pred_before=qfind.prediction if qfind is not None and qfind.prediction is not None else preds[0],
        pred_after=preds[-1], errors=errors,
        lattice=lattice, verdict=verdict, band_note=band_note, frf=frf, frf_terms=frf_terms,
        simulate_note="; ".join(x for x in (note, qnote) if x),
    )  # fmt: skip


__all__ = ["Diagnosis", "Finding", "Options", "available_memory", "check_memory", "diagnose", "heldout_residual",
           "memory_estimate", "output_worse", "prepare"]

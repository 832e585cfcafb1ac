"""Effects present in part of a recording: a vocabulary term switched on at a time ``t0``.

A term with one coefficient over the whole training part cannot name a force that
appears half-way (a LuGre element from mid-run, a friction that sets in when something
warms up): fitted over the whole training part its coefficient is a compromise, each
fold before the onset is predicted wrong, and the sign-flip test of
:mod:`servo.diagnose.select` sees losses there and gains after.  This module tries each
eligible vocabulary term **gated in time**: its columns multiplied by the indicator of
``t >= t0`` (the parameter ``from_s``, in s), ``t0`` one more nonlinear parameter.

* **Where ``t0`` comes from.**  From the training part only, inside the blocked
  cross-validation exactly as a Dahl length or a Stribeck velocity: the grid is the
  starts of the gain blocks (39 with the defaults; the first is excluded, a term gated
  from the first row is the ungated term already tried), and for each fold the pair
  (term parameters, ``t0``) with the lowest SSE on the other folds is chosen; the
  held-out fold is then scored with it (nested, so the choice of ``t0`` does not
  flatter the held-out gains).  On gain-block boundaries the gated Gram matrices are
  the ungated ones with the term's rows and columns zeroed in the blocks before ``t0``,
  so the 39 onsets cost no more column passes than one.  The gate is applied to the
  rows (``t_rows >= t0``), not to the full-rate columns before the rows' filter: the
  two differ within the decimation filter's reach of ``t0`` only (~15 rows).
* **The test** is the selection's (:class:`servo.diagnose.select.Score`): sign-flip test
  of the per-gain-block log gains, and the information criterion with ``k`` counting
  ``t0`` as one more parameter, that criterion taken with the term refined (its
  onset to the sample): of the gated candidates whose sign-flip test passes, the one
  with the lowest refined criterion is added (:func:`ranked`), not the one whose grid
  point scored best.  The level is the family-wise one with the gated
  candidates *counted among the candidates* of the round that ended the vocabulary
  stage: ``alpha/(N + M)`` with ``N`` the terms that round tested and ``M`` the gated
  ones (as if all had been tried together).
* **When it runs** (:func:`located`): only after the vocabulary stage has stopped, and
  only when the current model's cross-validated residual on the *training* part stands
  above its noise floor in some time window (the verdict's window check,
  :func:`servo.diagnose.verdict.window_checks`, on the training windows only, and on
  every usable row: the verdict itself leaves out the rows beside a rest,
  :func:`servo.diagnose.verdict.window_rows`, where a stick's misfit leaks; here such
  a leak only costs a gated round, which has its own level): a model that already
  predicts its training part to its noise has nothing a gate could explain.
  The test part is used neither for the trigger nor for the choice; it proves the
  finding like every other (:mod:`servo.diagnose.job`).  When that proof drops a term
  of the vocabulary stage (a ``drift`` the test part refuses: it, too, explains a
  change in time), this stage is run again on the model the proof keeps
  (:func:`servo.diagnose.job._regate`).
* **Which terms** (:func:`gateable`): column terms eligible on the current model,
  except screened ones (a mode or a cogging appearing mid-run: 1000-3000 variants times
  39 onsets, not built) and the inertia (a mass does not appear).  Input terms (a delay,
  a saturation) have no columns to gate; a saturation that sets in late changes the
  target, and is left to the verdict (``unexplained`` with the gap located).

Only onsets are built ("present from ``t0`` on"): an effect that stops before the test
part cannot be proven on it, and one that stops inside it is not modelled.  The final
model (``final_model.toml``) has no switch: it holds the term throughout and describes
the recording from ``t0`` on (which covers the test part), and the report says so.
"""
from __future__ import annotations

import numpy as np
from scipy import optimize

from servo.diagnose import verdict as verdict_mod
from servo.diagnose.fit import fit_model
from servo.diagnose.model import GATE, Model, Term
from servo.diagnose.select import Grams, Score, Selector, fit_rows, integrated_time, signflip_test, solve
from servo.diagnose.terms import VOCABULARY
from servo.io import progress

#: rows scanned either side of the chosen gain-block boundary when refining ``t0``
FINE_STEPS = 40


def onset(params: dict) -> float | None:
    """The onset of a gated term's parameters (s), None for an ungated term."""
    return params.get(GATE)


def gateable(sel: Selector, model: Model) -> list:
    """Vocabulary terms that may be tried gated on ``model`` (module doc): eligible
    column terms, not screened, not the inertia, not a correction of a model file's."""
    ok = []
    for name in sel.eligible(model)[0]:
        phys = VOCABULARY[name]
        if phys.path.kind != "column" or phys.search.screening or not phys.search.gated or model.corrects(name):
            continue
        ok.append(name)
    return ok


def located(sel: Selector, model: Model, alpha: float) -> list:
    """Time windows of the training part (``[t0, t1]`` pairs) where ``model``'s
    cross-validated residual stands above its noise floor (the verdict's window check,
    restricted to the training part); empty: no gate is tried."""
    d = sel.d
    y, Phi, _ = d.matrix(model)
    grams = Grams.of(Phi, y, sel.blocks)
    r = np.zeros(d.sig.m)
    for b, sl in enumerate(sel.blocks.slices):
        c, _ = grams.fold(b)
        r[sl] = y[sl] - Phi[sl] @ c
    w = d.train_valid
    first, last = np.flatnonzero(w)[[0, -1]]
    tau = integrated_time(np.where(w, r, 0.0)[first : last + 1])
    fit = fit_model(d, model)
    J = fit.mass()
    floor = verdict_mod.force_floor(d.sig, J)
    return [[x["t0"], x["t1"]] for x in verdict_mod.window_checks(d, r, floor, tau, alpha) if x["flagged"]
            and not x["test_part"]]  # fmt: skip


def _boundaries(sel: Selector) -> list:
    """Candidate onsets: ``(j0, row)`` for every gain block but the first, ``row`` its
    first row."""
    return [(j, sl.start) for j, sl in enumerate(sel.blocks.subs) if j > 0]


def _gated_grams(gr: Grams, new: slice, j0: int) -> Grams:
    """The Grams of the same columns with those of ``new`` zeroed in gain blocks
    ``< j0`` (the gate switches on at the start of gain block ``j0``)."""
    Gs, gs = gr.Gs.copy(), gr.gs.copy()
    Gs[:j0, new, :] = 0.0
    Gs[:j0, :, new] = 0.0
    gs[:j0, new] = 0.0
    K, q = gr.G.shape[0], gr.G.shape[1]
    G, g = np.zeros((K, q, q)), np.zeros((K, q))
    np.add.at(G, gr.sub_fold, Gs)
    np.add.at(g, gr.sub_fold, gs)
    return Grams(Gs, gs, gr.ss, gr.sub_fold, G, g, gr.s)


def score(sel: Selector, model: Model, physics: str) -> Score:
    """Score ``physics`` gated from an onset chosen inside each fold (module doc) on top
    of ``model``.  ``Score.thetas`` hold each fold's parameters with ``from_s``."""
    model = model.refitted(keep=physics)
    phys = VOCABULARY[physics]
    d = sel.d
    sc = Score(physics)
    grid = phys.grid(d, model)
    onsets = _boundaries(sel)
    if not grid or not onsets:
        sc.note = "not testable gated on these data (no parameter range the rows can see)"
        return sc
    y0, Phi, _, _ = sel.current(model)
    S0 = Grams.of(Phi, y0, sel.blocks).cv()
    p = Phi.shape[1]
    new = slice(p, p + len(phys.coefs))
    t_rows = d.sig.t_rows
    K = sel.blocks.K
    best = [None] * K  # per fold: (training SSE, theta, held-out SSE of its gain blocks)
    for th in grid:
        C = d.term_rows(Term.make(physics, th), model)
        gr = Grams.of(np.column_stack([Phi, C]), y0, sel.blocks)
        for j0, row in onsets:
            gg = _gated_grams(gr, new, j0)
            Gtot, gtot, stot = gg.G.sum(0), gg.g.sum(0), gg.s.sum()
            for b in range(K):
                Gt, gt = Gtot - gg.G[b], gtot - gg.g[b]
                c = solve(Gt, gt)
                sse = float(stot - gg.s[b] - 2 * c @ gt + c @ Gt @ c)
                if best[b] is None or sse < best[b][0]:
                    best[b] = (sse, {**th, GATE: float(t_rows[row])}, gg, c)
    S1 = np.concatenate([bb[2].heldout(b, bb[3]) for b, bb in enumerate(best)])
    sc.thetas = [bb[1] for bb in best]
    sc.S0, sc.S1 = S0, S1
    sc.t, sc.p = signflip_test(S0, S1)
    sc.k = len(phys.coefs) + len(phys.thetas) + 1  # the onset is a parameter too
    ratio = S1.sum() / max(S0.sum(), 1e-300)
    sc.delta_ic = float(sel.n_eff * np.log(max(ratio, 1e-300)) + sc.k * np.log(sel.n_eff))
    return sc


def _exact_onset(sel: Selector, model: Model, physics: str, theta: dict, y0, Phi, w) -> float:
    """The onset (s) within +-1.5 row spacings of ``theta``'s, sample by sample, with
    the least training SSE of the exact gated rows (the term's other parameters held)."""
    d = sel.d
    sig = d.sig
    phys = VOCABULARY[physics]
    p = {k: v for k, v in theta.items() if k != GATE}
    dd = d.column_design(phys, model)  # a sensor lag in the model: the arm's motion, rows through the lag
    F = np.atleast_2d(phys.full(dd, p, d.u_eff(model)).T).T
    k0 = int(np.searchsorted(sig.t, theta[GATE]))
    q = sig.settings.decimate
    last = int(sig.keep[np.flatnonzero(d.train_rows)[-1]])
    best = (np.inf, theta[GATE])
    for k in range(max(k0 - (3 * q) // 2, 1), min(k0 + (3 * q) // 2, last) + 1):
        G = F * (np.arange(sig.n) >= k)[:, None]
        C = np.column_stack([dd.sig.rows(np.ascontiguousarray(G[:, j])) for j in range(G.shape[1])])
        Z = np.column_stack([Phi, C])
        r = (y0 - Z @ fit_rows(y0, Z, w))[w]
        e = float(r @ r)
        if e < best[0]:
            best = (e, float(sig.t[k]))
    return best[1]


def refine(sel: Selector, model: Model, physics: str, thetas: list) -> tuple[Term, dict]:
    """The gated term's parameters on all training rows: the best of the folds' choices,
    its onset then scanned row by row around that gain-block boundary (the term's
    parameters held), then its nonlinear parameter (if one) refined by a bounded search
    with the onset held, as :meth:`Selector.refine` does for an ungated term.  Returns
    the term and the std of its nonlinear parameters (none for the onset: the profile
    of a step is not smooth; its resolution is the rows' spacing)."""
    model = model.refitted(keep=physics)
    phys = VOCABULARY[physics]
    d = sel.d
    t_rows = d.sig.t_rows

    w = sel.blocks.weights > 0
    y0, Phi, _, _ = sel.current(model)

    def approx_sse(th):  # the rows gated, as in the search
        C = d.term_rows(Term.make(physics, {k: v for k, v in th.items() if k != GATE}), model)
        g = (t_rows >= th[GATE]).astype(float)
        Z = np.column_stack([Phi, C * (g[:, None] if C.ndim == 2 else g)])
        r = (y0 - Z @ fit_rows(y0, Z, w))[w]
        return float(r @ r)

    def sse(th):  # exact: the full-rate columns gated (Design.term_rows)
        return sel.train_sse(model, Term.make(physics, th))

    uniq = {tuple(sorted(th.items())): th for th in thetas}.values()
    best = dict(min(uniq, key=approx_sse))
    # the onset, row by row within a gain block either side of the chosen boundary
    i0 = int(np.searchsorted(t_rows, best[GATE]))
    subs = sel.blocks.subs
    j = next((k for k, sl in enumerate(subs) if sl.start == i0), None)
    lo = subs[j - 1].start if j else i0
    hi = subs[j + 1].start if j is not None and j + 1 < len(subs) else min(i0 + 1, t_rows.size)
    last_train = int(np.flatnonzero(d.train_rows)[-1])
    rows = np.unique(np.linspace(max(lo, 1), min(hi, last_train), 2 * FINE_STEPS + 1).astype(int))
    cands = [{**best, GATE: float(t_rows[r])} for r in rows] + [best]
    best = dict(min(cands, key=approx_sse))
    # then sample by sample within +-1.5 rows, the full-rate columns gated (exact): a
    # force that steps at its onset leaves a residual spike where the gate is a row off
    best[GATE] = _exact_onset(sel, model, physics, best, y0, Phi, w)
    std: dict = {}
    if phys.thetas:  # each nonlinear parameter in turn, the others held (one sweep)
        names = [n for n in phys.thetas if n not in phys.search.held(best)]
        bounds = phys.bounds(d, model)
        logs = [bounds[n][2] for n in names]
        for name, lg in zip(names, logs):
            lo_b, hi_b, _ = bounds[name]
            span = sel._bracket(phys, best, name, lo_b, hi_b, lg)  # the ungated refinement's interval
            to = np.exp if lg else float

            def f1(z, name=name, to=to):
                return sse({**best, name: float(to(z))})

            if span[1] > span[0]:
                res = optimize.minimize_scalar(f1, bounds=span, method="bounded",
                                               options={"xatol": 1e-4 * (span[1] - span[0])})  # fmt: skip
                if res.fun <= sse(best):
                    best[name] = float(to(res.x))

        def f(zz):
            zz = np.atleast_1d(zz)
            return sse({**best, **{n: float(np.exp(v) if lg else v) for n, v, lg in zip(names, zz, logs)}})

        z = np.array([np.log(best[n]) if lg else best[n] for n, lg in zip(names, logs)])
        std = sel._theta_std(f, z, names, logs, {n: best[n] for n in names})
    return Term.make(physics, best), std


def ranked(sel: Selector, model: Model, tested: list) -> list:
    """The gated candidates whose sign-flip test passed (their :class:`Score`), each
    refined (:func:`refine`: its onset to the sample) and judged by the information
    criterion with the refined term: ``n_eff*ln(S1/S0) + k*ln(n_eff)``, ``S1`` the pooled
    SSE of each fold's blocks predicted by linear coefficients fitted on the other folds,
    the onset and the term's nonlinear parameter held at their refined values.  Those
    two were fitted on every training row, so ``S1`` is not held out for them: it is a
    fit criterion penalised by ``k*ln(n_eff)``, not a held-out one.  Sets each score's
    ``refined_ic``; returns ``[(term, score, theta_std), ...]`` in increasing order of
    it, the one to add first.

    The test scores a gated term with its onset on a gain block's boundary (a fortieth
    of the training part) and its other parameters on a grid.  A force that steps on at
    its onset is predicted wrong on every row between the grid's onset and the true
    one; a Stribeck bump, which rises with the speed, much less.  On the grid, a LuGre
    element from half-way put a Stribeck bump ahead (pooled held-out SSE 0.21 of the
    model's, the Dahl hysteresis 0.40), or left the hysteresis above the criterion
    (0.77 of the model's, ``p`` 5e-5); refined, the hysteresis is at 0.015, the bump at
    0.20.  The level is the sign-flip test's, on the folds' own (nested) choices: the
    refined criterion ranks the candidates and guards against a negligible gain; it
    admits nothing whose test failed."""
    out = []
    for s in tested:
        term, tstd = refine(sel, model, s.physics, s.thetas)
        y, Phi, _ = sel.d.matrix(model.refitted(keep=s.physics).plus(term))
        S1 = float(Grams.of(Phi, y, sel.blocks).cv().sum())
        s.refined_ic = float(sel.n_eff * np.log(max(S1 / max(s.S0.sum(), 1e-300), 1e-300)) + s.k * np.log(sel.n_eff))
        out.append((s.refined_ic, term, s, tstd))
    out.sort(key=lambda x: x[0])
    return [x[1:] for x in out]


def rounds(sel: Selector, model: Model, alpha: float, counted: int, room: int, log: list, not_testable: dict,
           implausible: dict) -> list:  # fmt: skip
    """The gated stage after the vocabulary's (module doc): rounds of the gated
    candidates at ``alpha/(counted + M)`` while the training part's residual is located
    in time and one pays, at most ``room`` findings.  ``counted`` is the number of
    candidates of the round that ended the vocabulary stage.  Appends each round to
    ``log`` (``{"level", "scores", "gated": True}``) and to ``not_testable`` and
    ``implausible``; returns the added ``(term, score, level, theta_std)``."""
    added: list = []
    while len(added) < room:
        cands = gateable(sel, model)
        if not cands or not located(sel, model, alpha):
            break
        sel.set_noise(model.refitted())
        scores = [score(sel, model, c) for c in progress.each(cands, f"terms gated in time, round {len(log) + 1}")]
        testable = [s for s in scores if s.S0 is not None]
        for s in scores:
            if s.S0 is None:
                not_testable[f"{s.physics} (gated in time)"] = s.note
        level = alpha / max(counted + len(testable), 1)
        log.append({"level": level, "scores": testable, "gated": True})
        found = None
        for term, best, tstd in ranked(sel, model, [s for s in testable if s.p < level]):
            if not best.passes(level):  # the criterion, with the refined term
                continue
            trial = fit_model(sel.d, model.plus(term).refitted())
            why = VOCABULARY[best.physics].judging.implausible_on(trial.term_params(len(trial.model.terms) - 1), sel.d)
            if why:
                implausible[f"{best.physics} (gated in time)"] = why
                continue
            found = (term, best, level, tstd)
            break
        if found is None:
            break
        added.append(found)
        model = model.plus(found[0])
    return added


__all__ = ["GATE", "gateable", "located", "onset", "ranked", "refine", "rounds", "score"]

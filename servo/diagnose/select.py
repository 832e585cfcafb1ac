"""Scoring candidates on held-out data and adding them greedily while they pay.

**Blocked cross-validation in time.**  The training rows are cut into ``K`` contiguous
blocks (default 10).  For fold ``b`` a model is fitted on the other blocks and predicts
block ``b``; its held-out sum of squares is ``S_b``.  Everything a fit needs is in the
per-block Gram matrices ``Z_b'Z_b``, ``Z_b'y_b``, ``y_b'y_b``, so each fold costs a small
solve, not a pass over the rows.  A candidate's nonlinear parameters (a Stribeck
velocity, a Dahl length, a mode frequency...) are chosen *inside* each fold on the
training blocks only (nested selection), so the held-out error of a term tuned over a
grid is not flattered by the tuning.

**The test.**  Each fold's held-out rows are scored in up to :data:`SUB_BLOCKS`
contiguous *gain blocks* (of at least :data:`MIN_SUB_ROWS` usable rows; 40 with the
defaults).  For the current model ``S0_j`` and the model with the candidate ``S1_j``,
``d_j = ln(S0_j/S1_j)`` (scale-free: an effect that lives near reversals improves the
blocks with many reversals by more in absolute terms, not in relative ones).  A
candidate pays when ``sum(d)`` is beyond what random signs give: a one-sided sign-flip
(randomisation) test, exact up to :data:`EXACT_FLIPS` blocks, :data:`N_FLIPS` draws with a
fixed seed beyond (:func:`signflip_test`), at level ``alpha/N`` with ``N`` the candidates
tried in that round (Bonferroni: under the null of nothing missing, the chance that any
of them passes the first round is at most ``alpha``).  The sign-flip test replaced a
t-test of ``mean(d)`` with the fold-overlap correction of Nadeau & Bengio (2003): that
test counted the *spread* of a real effect between blocks as noise, so a hysteresis
that lowered every block's held-out error (88-97 % in all) was rejected; a term that
lowers every gain block has ``p = 2^-N`` here.  It must also lower an information
criterion on the pooled held-out error, ``n_eff*ln(S1/S0) + k*ln(n_eff) < 0`` (BIC with
``k`` the added parameters, linear and nonlinear, and ``n_eff`` the number of training
rows divided by the residual's integrated autocorrelation time: the rows are filtered,
so neighbours are not independent).  Of the candidates that pay, the one with the
lowest criterion is added, its nonlinear parameters refined on all training rows, and
the next round starts from the augmented model.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import optimize, stats
from scipy.fft import next_fast_len

from servo.diagnose.model import Design, Model, Term
from servo.diagnose.terms import VOCABULARY

ALPHA = 0.05
N_BLOCKS = 10
#: each fold's held-out rows are scored in up to this many contiguous gain blocks ...
SUB_BLOCKS = 4
#: ... of at least this many usable rows
MIN_SUB_ROWS = 25
#: random sign vectors of the sign-flip test (beyond :data:`EXACT_FLIPS` gain blocks)
N_FLIPS = 20000
#: up to this many gain blocks the sign-flip distribution is enumerated exactly
EXACT_FLIPS = 14
EIG_FLOOR = 1e-11
#: variants of a screened candidate evaluated together
SCREEN_CHUNK = 32
#: a term with approximate rows (:meth:`~servo.physics.base.Search.coarse_batch`) is
#: built exactly for the variants that rank among the best this many in some fold by
#: those rows (the union over the folds); its folds then choose among them exactly
SHORTLIST = 4


# ------------------------------------------------------------------------ linear algebra
def solve(G: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Least-squares coefficients from a Gram matrix ``G`` (q, q) and ``g = Z'y`` (q,),
    columns scaled to unit norm and near-null directions dropped (a column the rows
    cannot tell from the others gets no weight instead of a huge one; so does a column
    whose entries are not finite, e.g. a memory term's state that diverged on rows it
    cannot follow)."""
    q = g.shape[0]
    if q == 0:
        return np.zeros(0)
    bad = ~(np.isfinite(np.diag(G)) & np.isfinite(g))
    if bad.any():
        G, g = np.where(bad[:, None] | bad[None, :], 0.0, G), np.where(bad, 0.0, g)
    d = np.sqrt(np.clip(np.diag(G), 0, None))
    d[d == 0] = 1.0
    Gs = G / np.outer(d, d)
    w, V = np.linalg.eigh(Gs)
    keep = w > EIG_FLOOR * max(w.max(), 1e-300)
    c = V[:, keep] @ ((V[:, keep].T @ (g / d)) / w[keep])
    return c / d


@dataclass
class Blocks:
    """Contiguous blocks of training rows: ``slices[b]`` the row range of fold ``b``
    (``K`` of them), ``subs[j]`` the row range of gain block ``j`` (each fold cut into
    contiguous sub-blocks, in order), ``sub_fold[j]`` the fold it belongs to,
    ``weights`` (m,) 1 for rows used by fits (training and valid), 0 otherwise."""

    slices: list
    weights: np.ndarray
    subs: list = field(default_factory=list)
    sub_fold: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def __post_init__(self):
        if not self.subs:
            self.subs = list(self.slices)
            self.sub_fold = np.arange(len(self.slices))

    @property
    def K(self) -> int:
        return len(self.slices)

    @property
    def N(self) -> int:
        """Number of gain blocks."""
        return len(self.subs)


def _cut(idx: np.ndarray, parts: int) -> list:
    """``parts`` contiguous row ranges over the sorted row indices ``idx``, equal in
    count; the first starts at ``idx[0]``, the last ends after ``idx[-1]``."""
    cuts = [idx[int(round(i * idx.size / parts))] for i in range(parts)] + [idx[-1] + 1]
    return [slice(cuts[i], cuts[i + 1]) for i in range(parts)]


#: gain blocks of the held-out test of a further finding (:func:`heldout_signflip`):
#: exact over all sign vectors, so its smallest p is 2^-12
HELDOUT_BLOCKS = 12


def heldout_signflip(r0: np.ndarray, r1: np.ndarray, rows: np.ndarray, blocks: int = HELDOUT_BLOCKS,
                     min_rows: int = MIN_SUB_ROWS) -> tuple[float, float, int]:  # fmt: skip
    """Whether a term earns its place on the held-out part: the residuals without
    (``r0``) and with it (``r1``, (m,) each, both models fitted on the training part)
    on the ``rows`` cut into up to ``blocks`` contiguous gain blocks of at least
    ``min_rows`` rows, and the sign-flip test (:func:`signflip_test`) of their sums of
    squares.  Returns ``(t, p, N)``: ``p`` the chance of a gain at least this consistent
    from a term that predicts nothing (the finding's chance of being spurious), ``N``
    the blocks; ``(0, 1, 0)`` when the rows make fewer than 4."""
    idx = np.flatnonzero(rows)
    n = min(int(blocks), idx.size // max(int(min_rows), 1))
    if n < 4:
        return 0.0, 1.0, 0
    parts = np.array_split(idx, n)
    S0 = np.array([float(r0[p] @ r0[p]) for p in parts])
    S1 = np.array([float(r1[p] @ r1[p]) for p in parts])
    t, p = signflip_test(S0, S1)
    return t, p, n


def make_blocks(train_valid: np.ndarray, K: int = N_BLOCKS, sub: int = SUB_BLOCKS, min_sub_rows: int = MIN_SUB_ROWS) -> Blocks:
    """``K`` contiguous folds over the training rows, equal in usable rows, each cut into
    up to ``sub`` gain blocks of at least ``min_sub_rows`` usable rows."""
    idx = np.flatnonzero(train_valid)
    folds = _cut(idx, K)
    per = max(1, min(int(sub), idx.size // (K * max(int(min_sub_rows), 1))))
    subs, owner = [], []
    for b, sl in enumerate(folds):
        fi = idx[(idx >= sl.start) & (idx < sl.stop)]
        parts = _cut(fi, per) if fi.size >= per else [sl]
        parts[0] = slice(sl.start, parts[0].stop)
        parts[-1] = slice(parts[-1].start, sl.stop)
        subs += parts
        owner += [b] * len(parts)
    return Blocks(folds, train_valid.astype(float), subs, np.array(owner))


@dataclass
class Grams:
    """Per gain block ``Z_j'Z_j`` (N, q, q), ``Z_j'y_j`` (N, q), ``y_j'y_j`` (N,), and
    their sums per fold ``G``, ``g``, ``s`` (K, ...)."""

    Gs: np.ndarray
    gs: np.ndarray
    ss: np.ndarray
    sub_fold: np.ndarray
    G: np.ndarray
    g: np.ndarray
    s: np.ndarray

    @classmethod
    def of(cls, Z: np.ndarray, y: np.ndarray, blocks: Blocks, same_Z: dict | None = None) -> "Grams":
        """The Grams of columns ``Z`` (m, q) and target ``y`` (m,) over ``blocks``.
        ``same_Z``: a dict shared by the calls that pass this very ``Z`` with other
        targets (an input term's variants change the target only): the first fills it
        with ``Z``'s used rows per gain block and their ``Z_j'Z_j``, the others reuse
        them (the same products of the same rows, to the bit)."""
        N, K, q = blocks.N, blocks.K, Z.shape[1]
        if same_Z is not None and same_Z.get("Z") is Z:
            Zbs, ws, Gs, G = same_Z["Zbs"], same_Z["ws"], same_Z["Gs"], same_Z["G"]
        else:
            Gs, Zbs, ws = np.zeros((N, q, q)), [], []
            for j, sl in enumerate(blocks.subs):
                w = blocks.weights[sl] > 0
                Zb = Z[sl][w]
                Gs[j] = Zb.T @ Zb
                Zbs.append(Zb)
                ws.append(w)
            G = np.zeros((K, q, q))
            np.add.at(G, blocks.sub_fold, Gs)
            if same_Z is not None:
                same_Z.update(Z=Z, Zbs=Zbs, ws=ws, Gs=Gs, G=G)
        gs, ss = np.zeros((N, q)), np.zeros(N)
        for j, sl in enumerate(blocks.subs):
            yb = y[sl][ws[j]]
            gs[j], ss[j] = Zbs[j].T @ yb, yb @ yb
        g, s = np.zeros((K, q)), np.zeros(K)
        np.add.at(g, blocks.sub_fold, gs)
        np.add.at(s, blocks.sub_fold, ss)
        return cls(Gs, gs, ss, blocks.sub_fold, G, g, s)

    def fold(self, b: int) -> tuple[np.ndarray, float]:
        """Coefficients fitted without fold ``b`` and their training SSE."""
        Gt, gt, st = self.G.sum(0) - self.G[b], self.g.sum(0) - self.g[b], self.s.sum() - self.s[b]
        c = solve(Gt, gt)
        return c, float(st - 2 * c @ gt + c @ Gt @ c)

    def heldout(self, b: int, c: np.ndarray) -> np.ndarray:
        """Held-out SSE of each gain block of fold ``b`` under coefficients ``c``."""
        j = self.sub_fold == b
        return self.ss[j] - 2 * self.gs[j] @ c + np.einsum("jpq,p,q->j", self.Gs[j], c, c)

    def cv(self) -> np.ndarray:
        """Held-out SSE of every gain block (N,), each predicted by the fit without its fold."""
        return np.concatenate([self.heldout(b, self.fold(b)[0]) for b in range(self.s.size)])


def screen_stats(C: np.ndarray, r: np.ndarray, blocks: Blocks) -> tuple[np.ndarray, np.ndarray]:
    """Per block ``C_b r_b`` (K, J, k) and ``C_b C_b'`` (K, J, k, k) of the columns ``C``
    (J, k, m) of ``J`` variants, over the usable rows (``r`` is zero elsewhere)."""
    K, J, k = blocks.K, C.shape[0], C.shape[1]
    a, H = np.zeros((K, J, k)), np.zeros((K, J, k, k))
    for b, sl in enumerate(blocks.slices):
        Cb = C[:, :, sl]
        w = blocks.weights[sl]
        a[b] = Cb @ r[sl]
        for i in range(k):
            Ci = Cb[:, i] * w
            for j in range(i, k):
                H[b, :, i, j] = H[b, :, j, i] = np.einsum("jm,jm->j", Ci, Cb[:, j])
    return a, H


def explained(A: np.ndarray, H: np.ndarray) -> np.ndarray:
    """``A'H^-1 A`` over the leading axes: the residual energy (K, J) that columns with
    Gram ``H`` (K, J, k, k) and correlation ``A`` (K, J, k) explain."""
    k = A.shape[-1]
    tr = np.trace(H, axis1=-2, axis2=-1)[..., None, None]
    Hr = H + np.eye(k) * (1e-12 * tr + 1e-300)
    return np.einsum("...k,...k->...", A, np.linalg.solve(Hr, A[..., None])[..., 0])


def fit_rows(y: np.ndarray, Phi: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Coefficients on the rows where ``w`` is true."""
    Z, yy = Phi[w], y[w]
    return solve(Z.T @ Z, Z.T @ yy)


def fft_len(n: int) -> int:
    """A fast FFT length for the linear (not circular) correlations of ``n`` samples:
    at least ``2n``.  Exactly ``2n`` can be a product with a large prime factor, for which
    an FFT of 150 000 points took 140 ms instead of 2 ms."""
    return next_fast_len(2 * n, real=True)


def integrated_time(r: np.ndarray, max_lag: int = 2000) -> float:
    """Integrated autocorrelation time of ``r`` (rows), ``1 + 2*sum(rho_k)`` with Sokal's
    window (stop at the first lag ``M >= 5*tau``); at least 1."""
    r = r - r.mean()
    n = r.size
    L = min(max_lag, n // 4)
    N = fft_len(n)
    f = np.fft.rfft(r, N)
    acf = np.fft.irfft(f * np.conj(f), N)[: L + 1]
    if acf[0] <= 0:
        return 1.0
    rho = acf / acf[0]
    tau = 1.0
    for k in range(1, L + 1):
        tau += 2 * rho[k]
        if k >= 5 * tau:
            break
    return float(max(tau, 1.0))


# ------------------------------------------------------------------------ scoring
@dataclass
class Score:
    """How a candidate did on held-out blocks against the current model.

    ``S0``/``S1`` (K,) held-out SSE per block without/with it; ``t``, ``p`` the corrected
    one-sided t-test; ``delta_ic`` the criterion; ``k`` parameters added; ``thetas`` the
    nonlinear parameters chosen in each fold; ``note`` why it was not testable;
    ``refined_ic`` the criterion with the parameters refined on all training rows, where
    a stage judges it so (a gated term: :func:`servo.diagnose.partial.ranked`), None
    elsewhere."""

    physics: str
    S0: np.ndarray | None = None
    S1: np.ndarray | None = None
    t: float = 0.0
    p: float = 1.0
    delta_ic: float = np.inf
    k: int = 0
    thetas: list = field(default_factory=list)
    note: str = ""
    refined_ic: float | None = None

    @property
    def improvement_pct(self) -> float:
        """Pooled held-out SSE reduction, % of the current model's."""
        if self.S0 is None:
            return 0.0
        return float(100 * (1 - self.S1.sum() / self.S0.sum()))

    def passes(self, level: float) -> bool:
        ic = self.delta_ic if self.refined_ic is None else self.refined_ic
        return self.S0 is not None and self.p < level and ic < 0


@lru_cache(maxsize=8)
def _signs(N: int) -> np.ndarray:
    """Sign vectors (S, N) of the sign-flip test: all ``2^N`` for a few blocks, else
    :data:`N_FLIPS` drawn with a fixed seed (the same test on every run)."""
    if N <= EXACT_FLIPS:
        k = np.arange(2**N)[:, None] >> np.arange(N)[None, :]
        return np.ascontiguousarray(1.0 - 2.0 * (k & 1), dtype=np.float32)
    return np.where(np.random.default_rng(20030101).random((N_FLIPS, N)) < 0.5, -1.0, 1.0).astype(np.float32)


def signflip_test(S0: np.ndarray, S1: np.ndarray) -> tuple[float, float]:
    """One-sided sign-flip (randomisation) test that the held-out SSE drops from ``S0``
    to ``S1`` (per gain block).  Returns ``(t, p)``: ``t = sum(d)/sqrt(sum(d^2))`` with
    ``d = ln(S0/S1)`` and ``p`` the share of sign vectors ``e`` with ``sum(e*|d|) >= sum(d)``.

    Under the null (the term predicts nothing) a block's gain is as likely to be a loss
    of the same size; the test needs no variance model, so an effect that is large in
    some blocks and absent in others (a hysteresis after a few reversals) is not
    penalised for the spread of its gains the way a t-test is: a term that lowers every
    block's error has ``p = 2^-N``."""
    d = np.log(np.maximum(S0, 1e-300) / np.maximum(S1, 1e-300))
    ss = float(np.sqrt(np.sum(d * d)))
    if not np.isfinite(ss) or ss == 0.0:
        return 0.0, 1.0
    T = float(d.sum())
    a = np.abs(d)
    E = _signs(d.size)  # float32: a quarter of the memory traffic; ties within 1e-5 count as reached
    null = E @ a.astype(np.float32)
    k = int(np.count_nonzero(null >= T - 1e-5 * float(a.sum())))
    p = k / E.shape[0] if d.size <= EXACT_FLIPS else (k + 1) / (E.shape[0] + 1)
    return T / ss, float(p)


def paired_test(S0: np.ndarray, S1: np.ndarray) -> tuple[float, float]:
    """One-sided corrected resampled t-test (Nadeau & Bengio 2003) that the held-out
    SSE drops from ``S0`` to ``S1`` (per block), the rule before the sign-flip test
    (kept for comparison in the tests).  Returns ``(t, p)``."""
    K = S0.size
    d = np.log(np.maximum(S0, 1e-300) / np.maximum(S1, 1e-300))
    sd = d.std(ddof=1)
    if not np.isfinite(sd) or sd == 0.0:
        return 0.0, 1.0
    t = d.mean() / (sd * np.sqrt(1.0 / K + 1.0 / (K - 1)))
    return float(t), float(stats.t.sf(t, K - 1))


class Selector:
    """Greedy forward selection on one recording's rows (see module doc)."""

    def __init__(self, design: Design, blocks: Blocks, alpha: float = ALPHA):
        self.d = design
        self.blocks = blocks
        self.alpha = alpha
        self.n_eff = float(blocks.weights.sum())
        self.tau = 1.0
        #: (model, current(model), its Grams' shared blocks, its held-out SSE): a round
        #: scores every candidate on top of the same model object
        self._base = None

    # ---- the current model ---------------------------------------------------------
    def current(self, model: Model):
        """``(y, Phi, names, c)`` of ``model``: its target and free columns
        (:meth:`Design.matrix`) and their coefficients fitted on the training rows; the
        arrays are read-only and shared by the calls with the same model object."""
        return self._baseline(model)[1]

    def _baseline(self, model: Model) -> tuple:
        if self._base is None or self._base[0] is not model:
            y, Phi, names = self.d.matrix(model)
            w = self.blocks.weights > 0
            c = fit_rows(y, Phi, w)
            for a in (y, Phi, c):
                a.setflags(write=False)
            self._base = (model, (y, Phi, names, c), {}, None)
        return self._base

    def _baseline_cv(self, model: Model) -> tuple[dict, np.ndarray]:
        """The Grams' shared blocks of ``model``'s columns (:meth:`Grams.of`'s ``same_Z``)
        and the held-out SSE of every gain block under ``model`` (read-only), computed
        once per model object."""
        m, cur, same, S0 = self._baseline(model)
        if S0 is None:
            y0, Phi = cur[0], cur[1]
            S0 = Grams.of(Phi, y0, self.blocks, same).cv()
            S0.setflags(write=False)
            self._base = (m, cur, same, S0)
        return same, S0

    def set_noise(self, model: Model) -> None:
        """Effective sample size from the model's training residual."""
        y, Phi, _, c = self.current(model)
        w = self.blocks.weights > 0
        r = np.where(w, y - Phi @ c, 0.0)
        self.tau = integrated_time(r[w.nonzero()[0][0] : w.nonzero()[0][-1] + 1])
        self.n_eff = float(w.sum()) / self.tau

    # ---- one candidate ----------------------------------------------------------------
    def score(self, model: Model, physics: str) -> Score:
        """Score ``physics`` on top of ``model``.  A model file's terms are refitted in
        the test (:meth:`Model.refitted`): the term is judged against the file's model
        structure, as against a fitted baseline, and a correction of a file's term
        against the file's value of that term with the others refitted."""
        model = model.refitted(keep=physics)
        phys = VOCABULARY[physics]
        sc = Score(physics)
        grid = phys.grid(self.d, model)
        if not grid:
            sc.note = "not testable on these data (no parameter range the rows can see)"
            return sc
        y0, Phi, _, _ = self.current(model)
        same_Phi, S0 = self._baseline_cv(model)  # an input term's variants change the target only
        K = self.blocks.K
        if phys.path.kind == "input":
            variants = [(th, *self._input_variant(model, physics, th, Phi)) for th in grid]
            choice = self._nested(variants, same_Phi)
        elif phys.search.screening and len(grid) > 1:
            choice = self._screened(model, physics, grid, y0, Phi)
        else:
            if len(grid) > SHORTLIST:
                grid = self._shortlist(model, physics, grid, y0, Phi)
            # one variant's columns at a time: a grid of 20 would otherwise hold 20 (m, q) matrices
            variants = ((th, np.column_stack([Phi, self.d.term_rows(Term.make(physics, th), model)]), y0) for th in grid)
            choice = self._nested(variants)
        S1 = np.concatenate([choice[b][1] for b in range(K)])
        sc.thetas = [choice[b][0] for b in range(K)]
        sc.S0, sc.S1 = S0, S1
        sc.t, sc.p = signflip_test(S0, S1)
        sc.k = len(phys.coefs) + len(phys.thetas)
        ratio = S1.sum() / max(S0.sum(), 1e-300)
        n_eff = self._n_eff_with(model, physics, sc.thetas, y0, Phi)
        sc.delta_ic = float(n_eff * np.log(max(ratio, 1e-300)) + sc.k * np.log(n_eff))
        return sc

    def _n_eff_with(self, model: Model, physics: str, thetas: list, y0: np.ndarray, Phi: np.ndarray) -> float:
        """The criterion's effective number of rows: the training rows over the integrated
        autocorrelation time of the residual the model *with* the candidate leaves (its
        variant chosen in most folds), at least the current model's count.  Under the null
        the two residuals agree; where the candidate removes a slow structure (a drift),
        the current model's residual counts that structure's own correlation as the
        noise's, and a term that whitens the residual would be charged for the structure
        it removes."""
        phys = VOCABULARY[physics]
        keys = [tuple(sorted(th.items())) for th in thetas]
        th = thetas[max(range(len(keys)), key=keys.count)]
        term = Term.make(physics, th)
        if phys.path.kind == "input":
            y, Z = self.d.target(model, extra=term), Phi
        else:
            y, Z = y0, np.column_stack([Phi, self.d.term_rows(term, model)])
        w = self.blocks.weights > 0
        r = np.where(w, y - Z @ fit_rows(y, Z, w), 0.0)
        idx = w.nonzero()[0]
        tau = integrated_time(r[idx[0] : idx[-1] + 1])
        return max(self.n_eff, float(w.sum()) / tau)

    def _input_variant(self, model, physics, theta, Phi):
        y = self.d.target(model, extra=Term.make(physics, theta))
        return Phi, y

    def _nested(self, variants, same_Z: dict | None = None) -> list:
        """Per fold: the variant with the lowest training SSE, and the held-out SSE of
        its gain blocks (``same_Z``: :meth:`Grams.of`'s, for variants that share their columns).
        ``variants`` is read once, in order: an iterator of ``(theta, Z, y)`` keeps one
        ``Z`` alive at a time."""
        grams = [(th, Grams.of(Z, y, self.blocks, same_Z)) for th, Z, y in variants]
        out = []
        for b in range(self.blocks.K):
            best = None
            for th, gr in grams:
                c, sse = gr.fold(b)
                if best is None or sse < best[0]:
                    best = (sse, th, gr.heldout(b, c))
            out.append((best[1], best[2]))
        return out

    def _shortlist(self, model, physics, grid, y0, Phi) -> list:
        """The variants of ``grid`` worth building exactly, in the grid's order: every
        one the term's approximate rows do not rank
        (:meth:`~servo.physics.base.Search.coarse_ranks`), and of those they do, the
        :data:`SHORTLIST` best of each fold by how much of the current model's training
        residual their approximate rows (:meth:`~servo.physics.base.Search.coarse_batch`,
        made orthogonal to ``Phi`` on the training rows) explain.  The folds then choose
        among them exactly (:meth:`_nested`): the same choice as over the whole grid
        wherever each fold's exact best is on the list (the Stribeck grid of 40
        variants: 1.3 s of its 1.7 s at 1e6 samples was building exact columns, 16 of
        them the bristles' traces, 47 ms each; load 6)."""
        phys = VOCABULARY[physics]
        ranked = [j for j, th in enumerate(grid) if phys.search.coarse_ranks(th)]
        C = phys.search.coarse_batch(self.d, [grid[j] for j in ranked], model) if len(ranked) > SHORTLIST else None
        if C is None:
            return grid
        w = self.blocks.weights > 0
        r = np.where(w, y0 - Phi @ fit_rows(y0, Phi, w), 0.0)
        if Phi.shape[1]:  # what the current columns already explain is not the variant's
            Cf = C.reshape(-1, C.shape[2])
            B = np.linalg.lstsq(Phi[w], Cf[:, w].T, rcond=None)[0]  # (p, J*k)
            C = (Cf - (Phi @ B).T).reshape(C.shape)
        a, H = screen_stats(C, r, self.blocks)
        expl = explained(a.sum(0)[None] - a, H.sum(0)[None] - H)  # (K, J): fold b's training blocks
        top = np.argsort(-expl, axis=1, kind="stable")[:, :SHORTLIST]
        keep = set(range(len(grid))) - set(ranked) | {ranked[j] for j in top.ravel().tolist()}
        return [grid[j] for j in sorted(keep)]

    def _screened(self, model, physics, grid, y0, Phi) -> list:
        """Per fold: scan the grid on the training blocks by how much of the current
        model's residual the approximate columns explain, then score the chosen
        variant with its exact columns."""
        phys = VOCABULARY[physics]
        w = self.blocks.weights > 0
        r = np.where(w, y0 - Phi @ fit_rows(y0, Phi, w), 0.0)
        K = self.blocks.K
        expl = np.zeros((K, len(grid)))
        sums = phys.search.screen_sums(self.d, grid, model, r, self.blocks)  # compiled, no columns
        for j0 in range(0, len(grid), SCREEN_CHUNK):
            if sums is None:
                C = phys.search.screen_batch(self.d, grid[j0 : j0 + SCREEN_CHUNK], model)  # (J, k, m)
                a, H = screen_stats(C, r, self.blocks)
            else:
                a, H = sums[0][:, j0 : j0 + SCREEN_CHUNK], sums[1][:, j0 : j0 + SCREEN_CHUNK]
            At, Ht = a.sum(0)[None] - a, H.sum(0)[None] - H  # fold b: all blocks but b
            expl[:, j0 : j0 + a.shape[1]] = explained(At, Ht)
        picks = expl.argmax(axis=1)
        out, cache = [], {}
        for b in range(K):
            j = int(picks[b])
            if j not in cache:
                Z = np.column_stack([Phi, self.d.term_rows(Term.make(physics, grid[j]), model)])
                cache[j] = Grams.of(Z, y0, self.blocks)
            c, _ = cache[j].fold(b)
            out.append((grid[j], cache[j].heldout(b, c)))  # the fold's gain blocks
        return out

    # ---- refinement on all training rows ----------------------------------------------
    def train_sse(self, model: Model, term: Term, approximate: bool = False) -> float:
        """Training SSE of ``model`` plus ``term``; ``approximate``: with the term's
        fast screening columns (for the local search of a screened term)."""
        w = self.blocks.weights > 0
        if approximate:
            y, Phi, _ = self.d.matrix(model)
            C = VOCABULARY[term.physics].search.screen(self.d, term.params, model)
            Phi = np.column_stack([Phi, C])
        else:
            y, Phi, _ = self.d.matrix(model.plus(term))
        c = fit_rows(y, Phi, w)
        r = (y - Phi @ c)[w]
        return float(r @ r)

    def refine(self, model: Model, physics: str, thetas: list) -> tuple[Term, dict]:
        """The candidate's nonlinear parameters on all training rows: the best of the
        folds' choices, then a bounded local search (variable projection: the linear
        coefficients are re-solved at every trial).  Returns the term and the standard
        deviation of each nonlinear parameter from the curvature of the profile.  A
        screened term (resonance, cogging) is searched with its fast columns."""
        phys = VOCABULARY[physics]
        if not phys.thetas:
            return Term.make(physics), {}
        model = model.refitted(keep=physics)  # as in :meth:`score`
        approx = phys.search.screening
        uniq = {tuple(sorted(th.items())): th for th in thetas}.values()
        best = min(uniq, key=lambda th: self.train_sse(model, Term.make(physics, th), approx))
        bounds = phys.bounds(self.d, model)
        kept = {n: best[n] for n in phys.search.held(best)}
        names = [n for n in phys.thetas if n not in kept]
        if not names:
            return Term.make(physics, best), {}
        logs = [bounds[n][2] for n in names]

        def to_theta(z):
            return {**kept, **{n: float(np.exp(v) if lg else v) for n, v, lg in zip(names, z, logs)}}

        def f(z):
            th = to_theta(np.atleast_1d(z))
            for n in names:
                lo, hi, _ = bounds[n]
                if not lo <= th[n] <= hi:
                    return np.inf
            return self.train_sse(model, Term.make(physics, th), approx)

        z0 = np.array([np.log(best[n]) if lg else best[n] for n, lg in zip(names, logs)])
        if len(names) == 1:
            lo, hi, lg = bounds[names[0]]
            span = self._bracket(phys, best, names[0], lo, hi, lg)
            res = optimize.minimize_scalar(f, bounds=span, method="bounded", options={"xatol": 1e-4 * (span[1] - span[0])})
            z = np.array([res.x]) if res.fun <= f(z0) else z0
        else:
            res = optimize.minimize(f, z0, method="Nelder-Mead", options={"maxfev": 60, "xatol": 1e-3, "fatol": 1e-9})
            z = res.x if res.fun <= f(z0) else z0
        if approx:  # polish with the exact columns, from the approximate optimum
            def fx(zz):
                th = to_theta(np.atleast_1d(zz))
                if any(not bounds[n][0] <= th[n] <= bounds[n][1] for n in names):
                    return np.inf
                return self.train_sse(model, Term.make(physics, th))

            steps = np.array([0.02 if lg else 1e-3 * max(abs(v), 1e-12) for v, lg in zip(z, logs)])
            simplex = np.vstack([z] + [z + np.diag(steps)[i] for i in range(z.size)])
            res = optimize.minimize(fx, z, method="Nelder-Mead",
                                    options={"initial_simplex": simplex, "maxfev": 15 * z.size, "xatol": 1e-4})  # fmt: skip
            if res.fun <= fx(z):
                z = np.atleast_1d(res.x)
            f = fx
        theta = to_theta(z)
        std = self._theta_std(f, z, names, logs, theta)
        return Term.make(physics, theta), std

    def _bracket(self, phys, best, name, lo, hi, lg):
        """Search interval around the best grid point: a factor 1.6 for scale
        parameters, one sample for a delay, 15 % for a level."""
        v = best[name]
        if lg:
            return (np.log(max(lo, v / 1.6)), np.log(min(hi, v * 1.6)))
        width = phys.search.refine_width(self.d, name, v)
        return (max(lo, v - width), min(hi, v + width))

    def _theta_std(self, f, z, names, logs, theta) -> dict:
        """Std of each nonlinear parameter: ``var = 2*s2*tau/f''`` from a central second
        difference of the profile SSE ``f`` (``s2`` the residual variance per row)."""
        w = self.blocks.weights > 0
        f0 = f(z)
        s2 = f0 / max(w.sum() - 1, 1)
        out = {}
        for i, (n, lg) in enumerate(zip(names, logs)):
            h = 1e-2 if lg else max(abs(z[i]) * 1e-2, 1e-3 * self.d.sig.dt)
            e = np.zeros_like(z)
            e[i] = h
            curv = (f(z + e) - 2 * f0 + f(z - e)) / h**2
            if not np.isfinite(curv) or curv <= 0:
                out[n] = float("inf")
                continue
            sd = np.sqrt(2 * s2 * self.tau / curv)
            out[n] = float(theta[n] * sd if lg else sd)
        return out

    # ---- the greedy loop ----------------------------------------------------------------
    def eligible(self, model: Model, exclude=()) -> tuple[list, dict]:
        ok, why = [], {}
        for name, phys in VOCABULARY.items():
            if name in exclude:
                continue
            reason = phys.search.eligible(model)
            if reason is None:
                ok.append(name)
            else:
                why[name] = reason
        return ok, why


__all__ = ["ALPHA", "Blocks", "Grams", "N_BLOCKS", "Score", "Selector", "HELDOUT_BLOCKS", "fit_rows", "fft_len", "heldout_signflip", "integrated_time",
           "make_blocks", "paired_test", "screen_stats", "signflip_test", "solve"]  # fmt: skip

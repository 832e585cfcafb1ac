"""Per-event evidence of a breakaway: each event's p-value against its local noise, and
their combination over events (docs/diagnosis.md, section 4b).

The breakaway test (:mod:`servo.diagnose.breakaway`) compares each event's peak held
force with the sliding level's switch through the filter plus a noise margin.  Counting
the events beyond a conservative bound throws away how far beyond (or how near) each
one is.  Here each event gets a **p-value**: the event's excess over the sliding level

    x = peak - (g*(Fc + Z_FC*std(Fc)) + MARGIN*Fc + pulse)            (F)

is compared with the null distribution of the sliding misfit's window maximum
``max |f - Fc*sgn(x')|`` over windows of the event's width, among the windows nearest the
event (the neighbourhood :func:`servo.diagnose.breakaway.noise_max` takes its quantile
over):

    p = (1 + K*q) / (1 + K)              where some window reaches x
    p = clip(Gumbel P(M >= x), P_FLOOR, 1/(1 + K))   beyond every one of them

``q`` the share of the neighbourhood's window positions whose maximum reaches ``x``,
``K`` the neighbourhood's number of windows (positions / width: about as many
independent ones), the usual "plus one" of an empirical p-value.  Beyond the largest of
them a Gumbel law fitted by moments to the neighbourhood's non-overlapping window maxima
extends the tail (the law of a maximum of many weakly dependent samples of light tail;
for a Gaussian maximum the moment fit's tail is heavier than the truth, so
conservative), floored at :data:`P_FLOOR` so that one event never carries more than
``ln P_FLOOR`` of the combined statistic.  That tail is a light-tailed law's: on a
correlated (AR(1), 0.6) misfit of Student-t samples an independent review measured
``P(p <= 1e-3)`` at 0.05 % for 30 degrees of freedom, 0.2 % for 8 and 0.6 % for 4 (and
``P(p <= 3e-4)`` 0.45 % for 4): heavy-tailed misfits get too many small p-values there;
the deterministic margins of the bound (``x`` is the excess over them) are what keep
the proving ground's and the project drive's nulls clean (docs/studies/2026-11-24-karnopp-per-event-evidence.md).
Where the arm slides too little for 20 windows of the event's width, the **union
bound** on the single samples of the whole sliding part: ``p = min(1, L*(1 + #{|e| >=
x})/(1 + n))``, ``L`` the window's width, ``n`` the sliding samples (the maximum of ``L``
samples reaches ``x`` only if one of them does, whatever their dependence; a Gaussian
law of the maximum of ``L`` independent samples, used first, gave correlated
heavy-tailed misfits 10 % of events at ``p <= 0.01``).  An event whose
peak does not point where the arm then moves (not a breakaway: ``toward`` false) has
``p = 1``.  Under the null (no breakaway) ``x`` stays below the window maximum it is
compared with or the deterministic margins put it lower still, so ``p`` is at least
uniform (the unit tests check it on fresh noise windows, and the union bound's branch
on heavy-tailed correlated noise).

The events' p-values are combined by the **truncated product** of those at or below
:data:`TAU` (Zaykin et al. 2002, its null law exact for independent uniform p-values,
at least as conservative for p-values that are at least uniform: :func:`truncated_product`;
the events are independent, separated by at least the filter's reach).  Three events far
beyond their noise prove a breakaway, and so do twenty each a little beyond (each at
``p <= TAU``), while events at rest that hold nothing (``p`` near 1, most of a
recording's) do not dilute the few that do, as they do Fisher's ``-2 sum ln p``
(with 7 of 22 events at ``p = 0.01`` and the rest at 1, Fisher's p-value is 0.024, the
truncated product's 8e-5; docs/studies/2026-11-24-karnopp-per-event-evidence.md).
"""
from __future__ import annotations

from collections import Counter

import numpy as np
from scipy import special, stats
from scipy.ndimage import maximum_filter1d

#: smallest p-value one event may have (its largest share of the log product: ln 1e-4 = -9.2)
P_FLOOR = 1e-4
#: the truncated product combines the events' p-values at or below this (``k`` of the
#: breakaway test counts them, and ``Fs`` is their median peak)
TAU = 0.1
#: Euler-Mascheroni constant (the Gumbel law's mean is ``mu + EULER*beta``)
EULER = 0.5772156649015329


def window_lengths(widths: np.ndarray) -> np.ndarray:
    """The sliding windows an event of each width is compared with: its width rounded
    up to a power of two (samples, (N,) int), so that events share window maxima."""
    return (2 ** np.ceil(np.log2(np.maximum(widths, 1)))).astype(int)


def nearest(pos: np.ndarray, centre: int, need: int) -> slice:
    """The ``need`` entries of the sorted window positions ``pos`` nearest ``centre``
    (the event's neighbourhood; the whole of ``pos`` when it holds fewer)."""
    i = int(np.searchsorted(pos, centre))
    lo, hi = max(0, i - need // 2), min(pos.size, i + need // 2)
    return slice(max(0, min(lo, hi - need)), min(pos.size, max(hi, lo + need)))


def gumbel_sf(x: float, maxima: np.ndarray) -> float:
    """``P(M >= x)`` under a Gumbel law fitted by moments to ``maxima`` ((k,), k >= 2)."""
    s = float(np.std(maxima, ddof=1))
    if not s > 0:
        return 0.0 if x > float(maxima[0]) else 1.0
    beta = s * np.sqrt(6.0) / np.pi
    mu = float(np.mean(maxima)) - EULER * beta
    return float(-np.expm1(-np.exp(-(x - mu) / beta)))


def union_bound(x: float, samples: np.ndarray, L: int) -> float:
    """``P(max of L consecutive samples >= x) <= L*P(|e| >= x)``, the single-sample tail
    read from ``samples`` (the sliding part's misfit, (n,)) with the empirical "plus one":
    valid whatever the samples' dependence (module doc)."""
    return float(min(1.0, L * (1.0 + np.count_nonzero(samples >= x)) / (1.0 + samples.size)))


def event_pvalues(abs_e: np.ndarray, outside: np.ndarray, widths: np.ndarray, centres: np.ndarray,
                  excess: np.ndarray, toward: np.ndarray, local_windows: int) -> np.ndarray:
    """(N,) each event's p-value (module doc): ``abs_e`` (n,) the sliding misfit ``|f -
    Fc*sgn(x')|`` (F), ``outside`` (n,) where the arm slides away from every event,
    ``widths``/``centres`` (N,) the events' widths and centres (full-rate samples),
    ``excess`` (N,) each peak's excess over the sliding level's switch and margins (F),
    ``toward`` (N,) whether each peak is a breakaway's direction, ``local_windows`` the neighbourhood's size in window widths."""
    p = np.ones(widths.size)
    z = np.where(outside, abs_e, np.inf)
    L_of = window_lengths(widths)
    for L in np.unique(L_of):
        sel = np.flatnonzero((L_of == L) & toward)
        if sel.size == 0:
            continue
        m = maximum_filter1d(z, size=int(L), mode="constant", cval=np.inf)
        ok = np.isfinite(m)
        pos = np.flatnonzero(ok)
        if pos.size < 20 * L:  # too few windows for a neighbourhood: the union bound
            zo = abs_e[outside]
            for j in sel:
                p[j] = max(union_bound(float(excess[j]), zo, int(L)), P_FLOOR)
            continue
        need = int(min(local_windows * L, pos.size))
        hoods = [nearest(pos, centres[j], need) for j in sel]
        # events that share a neighbourhood (near the ends; every event of a recording
        # shorter than the neighbourhood) count their maxima in it sorted once
        shared = Counter((h.start, h.stop) for h in hoods)
        kept: dict = {}
        for j, h in zip(sel, hoods):
            key = (h.start, h.stop)
            x = float(excess[j])
            if shared[key] > 1:
                if key not in kept:
                    loc = m[pos[h]]
                    kept[key] = loc, np.sort(loc)
                loc, ordered = kept[key]
                above = loc.size - int(np.searchsorted(ordered, x, side="left"))
            else:
                loc = m[pos[h]]
                above = int(np.count_nonzero(loc >= x))
            n_eff = loc.size / L  # about as many independent windows
            emp = float(above) / loc.size
            if emp > 0:
                p[j] = min(1.0, (1.0 + n_eff * emp) / (1.0 + n_eff))
            else:  # beyond every window of the neighbourhood: the Gumbel tail, within (P_FLOOR, 1/(1 + n_eff))
                blocks = loc[:: int(L)]
                gum = gumbel_sf(x, blocks) if blocks.size >= 2 else 1.0
                p[j] = max(P_FLOOR, min(gum, 1.0 / (1.0 + n_eff)))
    return p


def truncated_product(p: np.ndarray, tau: float = TAU) -> float:
    """The truncated product method's p-value (Zaykin et al. 2002): ``W`` the product of the
    p-values at or below ``tau`` (1 when none), its exact null tail for ``N`` independent
    uniform p-values: ``sum_k C(N,k) (1-tau)^(N-k) sum_{s<k} (k ln tau - ln W)^s/s! * w``
    with ``w = W`` where ``W <= tau^k``, else ``tau^k`` (the product of ``k`` values at or
    below ``tau`` is then certainly at most ``W``) and the inner sum dropped."""
    n = int(p.size)
    small = p[p <= tau]
    if small.size == 0:
        return 1.0
    lw = float(np.sum(np.log(small)))
    total = 0.0
    for k in range(1, n + 1):
        ck = float(stats.binom.pmf(k, n, tau))  # C(N,k) tau^k (1-tau)^(N-k)
        if ck == 0.0:
            continue
        klt = k * np.log(tau)
        if lw <= klt:
            # P(prod of k iid U(0,tau) <= W) = (W/tau^k) * sum_{s<k} (ln(tau^k/W))^s/s!
            t = klt - lw
            s = np.arange(k)
            terms = np.exp(s * np.log(t) - _lgamma1(s)) if t > 0 else (s == 0).astype(float)
            total += ck * float(np.exp(lw - klt)) * float(terms.sum())
        else:
            total += ck
    return float(min(1.0, total))


def _lgamma1(s: np.ndarray) -> np.ndarray:
    return special.gammaln(s + 1.0)


def combine(p: np.ndarray) -> float:
    """The test's p-value over the events' p-values ``p`` ((N,)): their truncated product at
    :data:`TAU` (module doc); 1 without events."""
    return truncated_product(p, TAU) if p.size else 1.0


__all__ = ["P_FLOOR", "TAU", "combine", "event_pvalues", "gumbel_sf", "nearest", "truncated_product", "union_bound",
           "window_lengths"]

"""Per-event evidence of a breakaway (servo/diagnose/breakaway_evidence.py).

Under the null an event's peak misfit is one more window maximum of the sliding misfit:
its p-value against the windows nearest it must be at least uniform, and the combined
test must keep its level over sets of such events, on fresh noise the p-values were not
built on.  With a breakaway, three events far above their noise prove it, and so do
twenty events each a little above.
"""
import numpy as np
import pytest
from scipy import signal

from servo.diagnose import breakaway_evidence as be

W = 40  # event width (samples): windows of 64
SPACING = 1000


def _noise(rng, n):
    """A correlated, slightly heavy-tailed misfit (|AR(1) of Student-t(8)|)."""
    z = rng.standard_t(8, n)
    return np.abs(signal.lfilter([1.0], [1.0, -0.6], z))


def _null_events(seed, n_ev=400):
    """Events whose peak is the maximum of fresh misfit over their own window (the null),
    masked out of the sliding part the p-values are measured on."""
    rng = np.random.default_rng(seed)
    n = n_ev * SPACING
    abs_e = _noise(rng, n)
    centres = np.arange(n_ev) * SPACING + SPACING // 2
    outside = np.ones(n, bool)
    peak = np.empty(n_ev)
    for j, c in enumerate(centres):
        outside[c - W // 2 : c + W // 2] = False
        peak[j] = abs_e[c - W // 2 : c + W // 2].max()
    return abs_e, outside, centres, peak


def _pvalues(abs_e, outside, centres, excess):
    n_ev = centres.size
    return be.event_pvalues(abs_e, outside, np.full(n_ev, W), centres, excess, np.ones(n_ev, bool), 100)


def test_event_pvalues_are_at_least_uniform_on_fresh_noise():
    abs_e, outside, centres, peak = _null_events(11)
    p = _pvalues(abs_e, outside, centres, peak)
    for a in (0.01, 0.05, 0.2, 0.5):
        se = np.sqrt(a * (1 - a) / p.size)
        assert np.mean(p <= a) <= a + 3 * se, a
    # and not degenerate: a null peak is often in the body of its neighbourhood's law
    assert np.mean(p <= 0.5) > 0.3
    # an event that does not point where the arm then moves holds no evidence
    q = be.event_pvalues(abs_e, outside, np.full(3, W), centres[:3], peak[:3] + 100, np.zeros(3, bool), 100)
    assert np.all(q == 1.0)


def test_combined_test_keeps_its_level_on_null_events():
    """Sets of 3, 8 and 25 null events (fresh noise): the combined p-value falls below a
    level no more often than the level (within three binomial standard errors)."""
    ps = np.concatenate([_pvalues(*ev[:3], ev[3]) for ev in map(_null_events, (21, 22, 23))])
    rng = np.random.default_rng(5)
    for N in (3, 8, 25):
        sets = [rng.choice(ps, N, replace=False) for _ in range(600)]
        comb = np.array([be.combine(s) for s in sets])
        for a in (0.05, 0.01):
            assert np.mean(comb < a) <= a + 3 * np.sqrt(a * (1 - a) / comb.size), (N, a)


@pytest.mark.slow
def test_truncated_product_is_calibrated_on_uniform_pvalues():
    """The truncated product's null law (Zaykin et al. 2002), checked on uniform p-values."""
    rng = np.random.default_rng(7)
    for N in (1, 4, 20):
        P = rng.random((2000, N))
        for tau in (0.05, be.TAU, 0.5):
            r = np.array([be.truncated_product(p, tau) for p in P])
            for a in (0.05, 0.01):
                assert abs(np.mean(r < a) - a) < 3 * np.sqrt(a * (1 - a) / 2000) + 0.002, (tau, N, a)


def test_a_few_events_beyond_their_noise_are_not_diluted_by_many_at_rest():
    """Seven of twenty-two events at p = 0.01 and the rest holding nothing: Fisher's
    combination would give 0.024; the truncated product keeps the evidence."""
    p = np.r_[np.full(7, 0.01), np.ones(15)]
    assert be.combine(p) < 1e-3
    assert be.combine(np.ones(22)) == 1.0


def test_few_strong_or_many_weak_events_prove_a_breakaway():
    abs_e, outside, centres, peak = _null_events(31, 60)
    # the law each event is compared with: the maximum over windows of 64 samples
    win = np.lib.stride_tricks.sliding_window_view(abs_e, 64)[::64].max(axis=1)
    q50, q95, q999 = np.quantile(win, [0.5, 0.95, 0.999])
    # three events held well above their noise, among twenty that hold nothing more
    strong = peak[:23].copy()
    strong[:3] = 2.0 * q999
    p = _pvalues(abs_e, outside, centres[:23], strong)
    assert be.combine(p) < 0.005
    assert be.combine(p[:3]) < 0.005  # three events alone
    # twenty events each a little above their noise (at its 95th percentile)
    assert be.combine(_pvalues(abs_e, outside, centres[:20], np.full(20, q95))) < 0.005
    # the same twenty at the noise's median: nothing
    assert be.combine(_pvalues(abs_e, outside, centres[:20], np.full(20, q50))) > 0.05


def test_pvalue_floor_limits_one_event():
    abs_e, outside, centres, peak = _null_events(41, 5)
    p = _pvalues(abs_e, outside, centres, np.full(5, 1e6))
    assert np.all(p == pytest.approx(be.P_FLOOR))


@pytest.mark.parametrize("dof", [4, 8])
def test_where_the_arm_slides_little_the_union_bound_keeps_the_level(dof):
    """Fewer than 20 windows of sliding samples: each event is judged by the union bound
    on the sliding samples' single-sample tail.  On correlated Student-t noise (AR(1),
    0.6) and events of 64 samples, spaced closer than 20 windows of sliding part, the
    p-values are at least uniform and sets of three combine at the level (the Gaussian
    law used before gave such noise 10 % of events at p <= 0.01)."""
    rng = np.random.default_rng(100 + dof)
    L, n_ev, per = 64, 8, 1000  # 8 events in 1000 samples: 488 sliding samples < 20*64
    ps = []
    for _ in range(300):
        z = np.abs(signal.lfilter([1.0], [1.0, -0.6], rng.standard_t(dof, per)))
        centres = np.linspace(60, per - 60, n_ev).astype(int)
        outside = np.ones(per, bool)
        peak = np.empty(n_ev)
        for j, c in enumerate(centres):
            outside[c - L // 2 : c + L // 2] = False
            peak[j] = z[c - L // 2 : c + L // 2].max()
        ps.append(be.event_pvalues(z, outside, np.full(n_ev, L), centres, peak, np.ones(n_ev, bool), 100))
    p = np.concatenate(ps)
    for a in (0.01, 0.05, 0.2):
        assert np.mean(p <= a) <= a + 3 * np.sqrt(a * (1 - a) / p.size), a
    comb = np.array([be.combine(q[:3]) for q in ps])
    assert np.mean(comb < 0.05) <= 0.05 + 3 * np.sqrt(0.05 * 0.95 / comb.size)


def _pvalues_by_scan(abs_e, outside, centres, excess, L, local_windows):
    """Each event's p-value as the per-event scan of its neighbourhood computed it."""
    from scipy.ndimage import maximum_filter1d

    m = maximum_filter1d(np.where(outside, abs_e, np.inf), size=L, mode="constant", cval=np.inf)
    pos = np.flatnonzero(np.isfinite(m))
    need = int(min(local_windows * L, pos.size))
    p = np.ones(centres.size)
    for j, c in enumerate(centres):
        loc = m[pos[be.nearest(pos, c, need)]]
        n_eff = loc.size / L
        emp = float(np.count_nonzero(loc >= excess[j])) / loc.size
        if emp > 0:
            p[j] = min(1.0, (1.0 + n_eff * emp) / (1.0 + n_eff))
        else:
            blocks = loc[::L]
            p[j] = max(be.P_FLOOR, min(be.gumbel_sf(float(excess[j]), blocks), 1.0 / (1.0 + n_eff)))
    return p


@pytest.mark.parametrize("local_windows", [3, 100])
def test_events_sharing_a_neighbourhood_get_the_scans_pvalues(local_windows):
    """Events that share their neighbourhood (every one of them where the recording is
    shorter than it: 100 windows; a few near the ends: 3) count its maxima once, sorted,
    and get the p-values the per-event scan gave, to the bit (excesses tied with a
    maximum included)."""
    abs_e, outside, centres, peak = _null_events(5, n_ev=60)
    L = int(be.window_lengths(np.array([W]))[0])
    m_values = np.sort(abs_e[outside])
    excess = peak.copy()
    excess[::7] = m_values[-3]  # exactly a sample's value: ">=" counts it
    excess[::11] = m_values[-1] + 1.0  # beyond every maximum: the Gumbel tail
    got = be.event_pvalues(abs_e, outside, np.full(centres.size, W), centres, excess, np.ones(centres.size, bool),
                           local_windows)  # fmt: skip
    want = _pvalues_by_scan(abs_e, outside, centres, excess, L, local_windows)
    assert got.tobytes() == want.tobytes()

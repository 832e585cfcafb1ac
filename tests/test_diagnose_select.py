"""The statistics of candidate selection: fold fits from Gram matrices, the sign-flip
test on gain blocks (and the t-test it replaced), the effective sample size, collinear
columns."""
import pytest
import numpy as np

from servo.diagnose.select import Grams, integrated_time, make_blocks, paired_test, signflip_test, solve


def test_fold_fits_from_grams_equal_direct_refits():
    rng = np.random.default_rng(0)
    m = 1000
    Z = rng.standard_normal((m, 3))
    y = Z @ [1.0, -2.0, 0.5] + rng.standard_normal(m)
    w = np.ones(m, bool)
    w[100:120] = False  # unusable rows are left out of every block
    blocks = make_blocks(w, 5, sub=3, min_sub_rows=25)
    assert blocks.N == 15 and list(blocks.sub_fold) == [b for b in range(5) for _ in range(3)]
    g = Grams.of(Z, y, blocks)
    cv = g.cv()
    for j, sl in enumerate(blocks.subs):
        mask = w.copy()
        mask[blocks.slices[blocks.sub_fold[j]]] = False  # the fit leaves out the whole fold
        c = np.linalg.lstsq(Z[mask], y[mask], rcond=None)[0]
        held = np.zeros(m, bool)
        held[sl] = True
        held &= w
        assert np.isclose(cv[j], np.sum((y[held] - Z[held] @ c) ** 2), rtol=1e-9)
    # the gain blocks tile each fold, in order
    for b, sl in enumerate(blocks.slices):
        mine = [blocks.subs[j] for j in np.flatnonzero(blocks.sub_fold == b)]
        assert mine[0].start == sl.start and mine[-1].stop == sl.stop
        assert all(a.stop == c.start for a, c in zip(mine[:-1], mine[1:]))


def test_paired_test():
    S0 = np.array([10.0, 12, 9, 11, 10, 13, 9, 10, 11, 12])
    assert paired_test(S0, S0) == (0.0, 1.0)
    t, p = paired_test(S0, 0.5 * S0 * (1 + 0.01 * np.arange(10)))
    assert t > 10 and p < 1e-6
    t, p = paired_test(S0, 1.1 * S0 * (1 + 0.01 * np.arange(10)))  # worse everywhere
    assert p > 0.99


def test_signflip_test():
    S0 = np.array([10.0, 12, 9, 11, 10, 13, 9, 10, 11, 12])
    assert signflip_test(S0, S0) == (0.0, 1.0)
    # every block improves, by very different amounts: p = 2^-N exactly (enumerated)
    t, p = signflip_test(S0, S0 * np.array([0.9, 0.99, 0.5, 0.95, 0.2, 0.97, 0.98, 0.9, 0.3, 0.99]))
    assert p == 2.0**-10
    t, p = signflip_test(S0, 1.1 * S0)  # worse everywhere
    assert p == 1.0
    # many blocks: a Monte Carlo distribution with a fixed seed, the same p on every call
    S0 = np.full(40, 10.0)
    S1 = S0 * np.where(np.arange(40) % 2 == 0, 0.5, 1.01)
    assert signflip_test(S0, S1) == signflip_test(S0, S1)
    assert signflip_test(S0, S1)[1] < 1e-3


def test_an_effect_in_a_few_blocks_passes_the_signflip_test_where_the_t_test_fails():
    """A column that matters in a third of the rows only (a hysteresis after a few
    reversals): the held-out error drops a lot there and not elsewhere.  The t-test of
    the mean log gain counts that spread as noise; the sign-flip test does not."""
    rng = np.random.default_rng(0)
    m = 4000
    blocks = make_blocks(np.ones(m, bool), 10)
    z = np.zeros(m)
    for k0 in rng.choice(m - 40, 8, replace=False):  # eight short transients
        z[k0 : k0 + 40] = np.exp(-np.arange(40) / 10.0)
    y = 1.0 + 3.0 * z + rng.standard_normal(m)
    X0 = np.ones((m, 1))
    S0, S1 = Grams.of(X0, y, blocks).cv(), Grams.of(np.column_stack([X0, z]), y, blocks).cv()
    assert 1 - S1.sum() / S0.sum() > 0.05
    assert signflip_test(S0, S1)[1] < 0.001
    fold0 = np.array([S0[blocks.sub_fold == b].sum() for b in range(10)])
    fold1 = np.array([S1[blocks.sub_fold == b].sum() for b in range(10)])
    assert paired_test(fold0, fold1)[1] > 0.02


@pytest.mark.slow
def test_signflip_false_alarm_rate_on_useless_columns():
    """Pure-noise candidates tried by blocked CV on white and on correlated residuals,
    one column and the best of a grid of five chosen inside each fold (nested, as a
    nonlinear parameter is): the test at 5 % rejects at most about 5 % of the time."""
    rng = np.random.default_rng(5)
    m = 2000
    blocks = make_blocks(np.ones(m, bool), 10)
    X0 = np.ones((m, 1))
    rej = {"one": 0, "grid": 0}
    for trial in range(200):
        e = rng.standard_normal(m + 8)
        y = np.convolve(e, np.ones(8) / 8, "valid")[:m] if trial % 2 else e[:m]  # tau 8 rows or white
        base = Grams.of(X0, y, blocks)
        S0 = base.cv()
        grams = [Grams.of(np.column_stack([X0, rng.standard_normal(m)]), y, blocks) for _ in range(5)]
        _, p = signflip_test(S0, grams[0].cv())
        rej["one"] += p < 0.05
        S1 = []
        for b in range(blocks.K):  # per fold, the variant with the lowest training SSE
            c, gr = min(((gr.fold(b), gr) for gr in grams), key=lambda x: x[0][1])
            S1.append(gr.heldout(b, c[0]))
        _, p = signflip_test(S0, np.concatenate(S1))
        rej["grid"] += p < 0.05
    assert rej["one"] <= 17 and rej["grid"] <= 17, rej  # 5 % of 200 is 10; binomial 99 % bound 17


def test_paired_test_false_alarm_rate_on_a_useless_column():
    """A pure-noise column tried by blocked CV on white residuals: the corrected test
    at 5 % rejects at most about 5 % of the time (200 trials)."""
    rng = np.random.default_rng(3)
    m, rej = 2000, 0
    blocks = make_blocks(np.ones(m, bool), 10)
    for _ in range(200):
        y = rng.standard_normal(m)
        X0 = np.ones((m, 1))
        X1 = np.column_stack([X0, rng.standard_normal(m)])
        _, p = paired_test(Grams.of(X0, y, blocks).cv(), Grams.of(X1, y, blocks).cv())
        rej += p < 0.05
    assert rej <= 16  # 5 % of 200 is 10; binomial 99 % bound 17


def test_integrated_time():
    rng = np.random.default_rng(1)
    assert integrated_time(rng.standard_normal(20000)) < 1.2
    e = rng.standard_normal(50000)
    ar = np.zeros_like(e)
    for k in range(1, e.size):
        ar[k] = 0.8 * ar[k - 1] + e[k]
    assert abs(integrated_time(ar) - 9.0) < 1.5  # (1 + rho)/(1 - rho)


def test_solve_gives_a_collinear_column_no_weight():
    rng = np.random.default_rng(2)
    a = rng.standard_normal(500)
    Z = np.column_stack([a, a, rng.standard_normal(500)])
    y = 3 * a
    c = solve(Z.T @ Z, Z.T @ y)
    assert np.allclose(Z @ c, y, atol=1e-9)
    assert np.all(np.abs(c) < 10)


def test_a_column_that_is_not_finite_gets_no_weight():
    """A candidate column with non-finite entries (a memory term's state that diverged)
    is given no weight, and the others are solved as without it, instead of the
    eigensolver failing on the Gram matrix (a closed-loop step recording at decimation
    3 raised ``LinAlgError`` through the hysteresis candidate)."""
    from servo.diagnose.select import solve

    rng = np.random.default_rng(0)
    Z = rng.standard_normal((200, 2))
    y = Z @ np.array([2.0, -1.0])
    Zb = np.column_stack([Z, np.full(200, np.nan)])
    c = solve(Zb.T @ Zb, Zb.T @ y)
    assert c[2] == 0.0 and np.allclose(c[:2], [2.0, -1.0])

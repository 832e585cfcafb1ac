"""The statistics of candidate selection: fold fits from Gram matrices, the corrected
paired test, the effective sample size, collinear columns."""
import numpy as np

from servo.diagnose.select import Grams, integrated_time, make_blocks, paired_test, solve


def test_fold_fits_from_grams_equal_direct_refits():
    rng = np.random.default_rng(0)
    m = 1000
    Z = rng.standard_normal((m, 3))
    y = Z @ [1.0, -2.0, 0.5] + rng.standard_normal(m)
    w = np.ones(m, bool)
    w[100:120] = False  # unusable rows are left out of every block
    blocks = make_blocks(w, 5)
    g = Grams.of(Z, y, blocks)
    cv = g.cv()
    for b, sl in enumerate(blocks.slices):
        mask = w.copy()
        mask[sl] = False
        c = np.linalg.lstsq(Z[mask], y[mask], rcond=None)[0]
        held = np.zeros(m, bool)
        held[sl] = True
        held &= w
        assert np.isclose(cv[b], np.sum((y[held] - Z[held] @ c) ** 2), rtol=1e-9)


def test_paired_test():
    S0 = np.array([10.0, 12, 9, 11, 10, 13, 9, 10, 11, 12])
    assert paired_test(S0, S0) == (0.0, 1.0)
    t, p = paired_test(S0, 0.5 * S0 * (1 + 0.01 * np.arange(10)))
    assert t > 10 and p < 1e-6
    t, p = paired_test(S0, 1.1 * S0 * (1 + 0.01 * np.arange(10)))  # worse everywhere
    assert p > 0.99


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

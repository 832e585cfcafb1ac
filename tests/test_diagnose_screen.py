"""The compiled screening sums of the large grids (cogging periods, mode frequencies and
dampings) equal the statistics of the columns the numpy path builds, and pick the same
variant."""
import numpy as np
import pytest
from scipy import signal

from kernels.screen import biquad_stats
from servo.diagnose import baseline as baseline_mod
from servo.diagnose.concealed import Scenario, concealed_recording
from servo.diagnose.job import Options, prepare
from servo.diagnose.select import explained, fit_rows, make_blocks, screen_stats
from servo.diagnose.terms import VOCABULARY
from servo.identify.regressors import RobustSettings


@pytest.fixture(scope="module")
def setup():
    rec, _ = concealed_recording("cogging", 2e-5, seed=3, scenario=Scenario(duration_s=1.0))
    d = prepare(rec, RobustSettings(), Options())
    blocks = make_blocks(d.train_valid, 10)
    base = baseline_mod.from_terms(None)
    y0, Phi, _ = d.matrix(base)
    w = blocks.weights > 0
    r = np.where(w, y0 - Phi @ fit_rows(y0, Phi, w), 0.0)
    return d, blocks, base, r


@pytest.mark.parametrize("physics", ["cogging", "resonance"])
def test_screen_sums_equal_the_columns_statistics(setup, physics):
    d, blocks, base, r = setup
    phys = VOCABULARY[physics]
    grid = phys.grid(d, base)
    assert len(grid) > 100
    a, H = phys.search.screen_sums(d, grid, base, r, blocks)
    a0, H0 = screen_stats(phys.search.screen_batch(d, grid, base), r, blocks)
    assert a.shape == a0.shape and H.shape == H0.shape
    assert np.allclose(a, a0, rtol=1e-9, atol=1e-12 * np.abs(a0).max())
    assert np.allclose(H, H0, rtol=1e-9, atol=1e-12 * np.abs(H0).max())

    def picks(a, H):
        return explained(a.sum(0)[None] - a, H.sum(0)[None] - H).argmax(axis=1)

    assert np.array_equal(picks(a, H), picks(a0, H0))


def test_cogging_finds_its_period_by_the_sums(setup):
    """The concealed cogging's period (50 um) is the screen's best variant in every fold."""
    d, blocks, base, r = setup
    phys = VOCABULARY["cogging"]
    grid = phys.grid(d, base)
    a, H = phys.search.screen_sums(d, grid, base, r, blocks)
    best = explained(a.sum(0)[None] - a, H.sum(0)[None] - H).argmax(axis=1)
    periods = np.array([grid[j]["period"] for j in best])
    assert np.all(np.abs(periods / 50e-6 - 1) < 0.02), periods


def test_biquad_stats_filters_as_lfilter():
    rng = np.random.default_rng(1)
    y = rng.standard_normal(3000)
    r = rng.standard_normal(3000)
    w = (rng.random(3000) > 0.1).astype(float)
    r *= w
    starts, stops = np.array([100, 1500]), np.array([1500, 2900])
    B, A = [], []
    for f, z in ((30.0, 0.01), (120.0, 0.05), (400.0, 0.2)):
        b, a = VOCABULARY["resonance"].biquad(f, z, 1000.0)
        B.append(b), A.append(a)
    B, A = np.array(B), np.array(A)
    a, H = np.empty((2, 3, 1)), np.empty((2, 3, 1, 1))
    biquad_stats(y, r, w, starts, stops, np.ascontiguousarray(B.T), np.ascontiguousarray(A.T), -1.0, a, H)
    for j in range(3):
        c = -signal.lfilter(B[j], A[j], y)
        for b in range(2):
            sl = slice(starts[b], stops[b])
            assert np.isclose(a[b, j, 0], c[sl] @ r[sl], rtol=1e-12)
            assert np.isclose(H[b, j, 0, 0], (w[sl] * c[sl]) @ c[sl], rtol=1e-12)

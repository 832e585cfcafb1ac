"""The rows' decimation (:func:`servo.diagnose.signals.decimate`) through its compiled
kernel (:func:`kernels.decimate.filtfilt_decimate`) is scipy's zero-phase filter and
slice to the bit, at every length, factor and filter order a diagnosis uses, and its
rows are compact arrays (no view keeping the full-rate column alive)."""
import numpy as np
import pytest
from scipy import signal

from servo.diagnose.signals import cheby_sos, decimate
from servo.identify.regressors import matlab_decimate


def _scipy(z, q, order=8, ripple_db=0.05):
    sos = signal.cheby1(order, ripple_db, 0.8 / q, output="sos")
    return signal.sosfiltfilt(sos, z, padlen=min(3 * order, z.size - 1))[slice((z.size - 1) % q, z.size, q)]


def _columns(n, rng):
    yield rng.standard_normal(n)  # white
    yield 1e-6 * np.cumsum(rng.standard_normal(n)) + 3e-3  # a slow position, offset
    yield 3e-4 * np.sign(np.sin(np.arange(n) / 37.0))  # a sign column (steps)


@pytest.mark.parametrize("q,order", [(10, 8), (5, 8), (8, 8), (3, 8), (2, 4), (10, 6)])
@pytest.mark.parametrize("n", [26, 27, 100, 1001, 4096, 50_003])
def test_decimate_is_scipys_filter_to_the_bit(q, order, n):
    rng = np.random.default_rng(n * 100 + q * 10 + order)
    for z in _columns(n, rng):
        got = decimate(z, q, order)
        ref = _scipy(z, q, order)
        assert got.shape == ref.shape == (-(-n // q),)
        assert np.array_equal(got, ref)
        assert got.flags.c_contiguous and got.flags.owndata  # compact, no full-rate view


def test_decimate_matches_the_identification_path():
    """The identification's MATLAB-style decimation (designed on every call) gives the
    same rows."""
    z = np.random.default_rng(5).standard_normal(20_000)
    assert np.array_equal(decimate(z, 10), matlab_decimate(z, 10))


def test_short_columns_and_views():
    """Shorter than the filter's padding: scipy's path (and its error for a column too
    short to pad); a strided view is filtered as its values; q = 1 is a copy."""
    z = np.random.default_rng(2).standard_normal(300)
    assert np.array_equal(decimate(z[::3], 10), _scipy(np.ascontiguousarray(z[::3]), 10))
    assert np.array_equal(decimate(z[:5], 2), _scipy(z[:5], 2))
    one = decimate(z, 1)
    assert np.array_equal(one, z) and one is not z
    assert cheby_sos(8, 0.05, 10).shape == (4, 6)

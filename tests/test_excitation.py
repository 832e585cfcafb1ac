"""Excitation signals: their spectra are what the docstrings promise (power on the
chosen band or lines, flat where promised, nothing elsewhere), their peak is the
amplitude, and impossible parameters are one error."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from servo.errors import ConfigError
from servo.scenarios.excitation import ExcitationError, chirp, multisine, multisine_lines, prbs, prbs_period

DT = 1e-4  # 10 kHz


@pytest.mark.parametrize("method", ["linear", "logarithmic"])
def test_chirp_puts_its_power_in_the_swept_band(method):
    n, f0, f1 = 2**16, 50.0, 1500.0
    x = chirp(n, DT, f0, f1, amplitude=0.3, method=method)
    assert x.shape == (n,) and x.dtype == np.float64
    assert np.max(np.abs(x)) == pytest.approx(0.3, rel=1e-6)
    f, P = signal.welch(x, 1 / DT, nperseg=2048, noverlap=1536)  # hann^2 sums flat at 75 %
    df = f[1]
    inside = (f >= f0 - 2 * df) & (f <= f1 + 2 * df)
    assert P[inside].sum() / P.sum() > 0.98
    core = (f > 1.5 * f0) & (f < f1 / 1.5)
    # linear sweep: equal time per Hz, flat PSD (slope 0 in log-log); log sweep: equal
    # time per decade, PSD ~ 1/f (slope -1)
    slope, icpt = np.polyfit(np.log10(f[core]), 10 * np.log10(P[core]), 1)
    want = -10.0 if method == "logarithmic" else 0.0
    assert slope == pytest.approx(want, abs=1.0)  # dB per decade
    ripple = 10 * np.log10(P[core]) - (slope * np.log10(f[core]) + icpt)
    assert np.sqrt(np.mean(ripple**2)) < 0.5  # dB


def test_multisine_has_equal_lines_exactly_where_asked_and_a_low_crest_factor():
    period, f_min, f_max = 4096, 20.0, 2000.0
    x = multisine(3 * period + 100, DT, f_min, f_max, amplitude=2e-3, period=period)
    assert np.max(np.abs(x)) == pytest.approx(2e-3, rel=1e-12)
    np.testing.assert_array_equal(x[period : 2 * period], x[:period])  # periodic
    X = np.abs(np.fft.rfft(x[:period]))
    lines = multisine_lines(period, DT, f_min, f_max)
    df = 1 / (period * DT)
    assert lines[0] * df >= f_min and (lines[0] - 1) * df < f_min
    assert lines[-1] * df <= f_max and (lines[-1] + 1) * df > f_max
    on = X[lines]
    assert on.max() / on.min() == pytest.approx(1.0, abs=1e-9)  # equal amplitudes
    off = np.delete(X, lines)
    assert off.max() < 1e-9 * on.max()  # no leakage, nothing else
    rms = np.sqrt(np.mean(x[:period] ** 2))
    crest = np.max(np.abs(x[:period])) / rms
    # Schroeder phases: well below random phases (~3-4 for ~800 lines), near a sine's sqrt(2)
    rng = np.random.default_rng(0)
    spec = np.zeros(period // 2 + 1, complex)
    spec[lines] = np.exp(2j * np.pi * rng.random(lines.size))
    rand = np.fft.irfft(spec, period)
    assert crest < 2.0 < np.max(np.abs(rand)) / np.sqrt(np.mean(rand**2))


def test_multisine_every_other_line_leaves_the_odd_ones_empty():
    period = 1000
    x = multisine(period, DT, 100.0, 1000.0, period=period, every=2)
    X = np.abs(np.fft.rfft(x))
    lines = multisine_lines(period, DT, 100.0, 1000.0, every=2)
    assert np.all(np.diff(lines) == 2)
    assert np.delete(X, lines).max() < 1e-9 * X[lines].min()


@pytest.mark.parametrize("nbits,hold", [(9, 1), (7, 4)])
def test_prbs_is_binary_periodic_and_flat_over_one_period(nbits, hold):
    N = prbs_period(nbits, hold)
    x = prbs(2 * N + 7, DT, amplitude=0.5, nbits=nbits, hold=hold)
    assert set(np.unique(x)) == {-0.5, 0.5}
    np.testing.assert_array_equal(x[N : 2 * N], x[:N])
    X = np.abs(np.fft.fft(x[:N])) ** 2
    bits = 2**nbits - 1
    k = np.arange(1, N // 2)
    # a maximum-length sequence: |X_k|^2 = (bits + 1) * a^2 on every line that is not a
    # multiple of the bit count, times the hold's sinc^2 envelope; DC holds a^2 hold^2
    envelope = (np.sinc(k / bits) / np.sinc(k / N)) ** 2 if hold > 1 else np.ones(k.size)
    expected = (bits + 1) * 0.25 * hold**2 * envelope
    live = envelope > 1e-6
    np.testing.assert_allclose(X[k][live], expected[live], rtol=1e-8)
    assert X[0] == pytest.approx(0.25 * hold**2, rel=1e-9)


def test_impossible_parameters_are_one_error_a_value_error_too():
    for call in (lambda: chirp(100, DT, 10.0, 6000.0), lambda: chirp(0, DT, 10.0, 100.0),
                 lambda: multisine(100, DT, 1.0, 20.0), lambda: multisine(1000, DT, 300.0, 200.0),
                 lambda: prbs(100, DT, nbits=1), lambda: prbs(100, DT, hold=0), lambda: prbs(100, -DT),
                 lambda: chirp(100, DT, 10.0, 100.0, amplitude=0.0)):  # fmt: skip
        with pytest.raises(ExcitationError) as e:
            call()
        assert isinstance(e.value, ConfigError) and isinstance(e.value, ValueError)
        assert "\n" not in str(e.value)

"""The project's one stepped-sine demodulator (servo/frf/sine.py), used by ``servo bode``
and ``servo loop``: a sine of known amplitude and phase in noise lands within its stated
uncertainty, a drift does not leak into it, and a known linear system (scipy.signal.dlti)
driven by a sine is read to its frequency response."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from servo.frf.sine import demodulate

FS = 20_000.0


def _window(f, periods):
    n = int(round(periods * FS / f))
    return periods * FS / n, np.arange(n) / FS  # the snapped frequency, whole periods in whole samples


def test_a_sine_in_white_noise_lands_within_its_stated_uncertainty():
    """400 windows of ``A cos(w t + phi)`` plus white noise: the error of each complex
    component over the stated standard error is standard normal (mean square 1, about
    4.6 % beyond 2), and the stated error is ``sigma*sqrt(2/n)``."""
    rng = np.random.default_rng(3)
    f, t = _window(437.0, 8)
    amp, phi, sigma = 2e-3, 0.7, 5e-3
    true = amp * np.exp(1j * phi)
    z = []
    for _ in range(400):
        y = 0.3 + amp * np.cos(2 * np.pi * f * t + phi) + sigma * rng.standard_normal(t.size)
        fit = demodulate(y, f, t, 8)
        e = (fit.amp[0] - true) / fit.std[0]
        z += [e.real, e.imag]
        assert fit.std[0] == pytest.approx(sigma * np.sqrt(2 / t.size), rel=0.15)
    z = np.array(z)
    assert 0.85 < np.mean(z**2) < 1.15
    assert 0.02 < np.mean(np.abs(z) > 2) < 0.075  # 4.55 % +- 3.5 binomial std of 800
    assert abs(np.mean(z)) < 0.1  # no bias


def test_the_fit_is_the_single_bin_dft_and_a_drift_does_not_leak_into_it():
    f, t = _window(1234.0, 6)
    y = 1.5e-3 * np.sin(2 * np.pi * f * t + 0.3)
    fit = demodulate(y, f, t, 6)
    dft = 2 / t.size * np.sum((y - y.mean()) * np.exp(-2j * np.pi * f * t))
    assert abs(fit.amp[0] - dft) < 1e-12 * abs(dft)
    assert abs(fit.amp[0] - 1.5e-3 * np.exp(1j * (0.3 - np.pi / 2))) < 1e-12
    drifting = y + 0.2 + 40.0 * t  # a slow transient, 40 units/s
    d = demodulate(drifting, f, t, 6)
    assert abs(d.amp[0] - fit.amp[0]) < 1e-10 * abs(fit.amp[0])
    assert d.fraction[0] == pytest.approx(1.0, abs=1e-9)
    assert np.allclose(d.per_period[:, 0], fit.amp[0], rtol=1e-8)


def test_a_known_linear_system_is_read_to_its_frequency_response():
    """A lightly damped dlti driven by a sine from rest: after its transient has decayed,
    output over input is the system's response at the snapped frequency, with a per-
    period spread (``SineFit.ratio``) near 0 and a random error that covers the noise."""
    sys = signal.dlti([0.02, 0.03], [1.0, -1.6, 0.8], dt=1 / FS)
    rng = np.random.default_rng(5)
    for f0 in (50.0, 900.0, 3000.0):
        f, tw = _window(f0, 10)
        settle = 4000
        t = np.arange(settle + tw.size) / FS
        u = 1e-3 * np.sin(2 * np.pi * f * t)
        _, y = signal.dlsim(sys, u)
        G = sys.freqresp([2 * np.pi * f / FS])[1][0]
        clean = demodulate(np.column_stack([y.ravel()[settle:], u[settle:]]), f, t[settle:], 10)
        H, sd = clean.ratio(0, 1)
        assert abs(H / G - 1) < 1e-6 and sd < 1e-6 * abs(G)
        noisy_y = y.ravel() + 2e-6 * rng.standard_normal(t.size)
        fit = demodulate(np.column_stack([noisy_y[settle:], u[settle:]]), f, t[settle:], 10)
        Hn, sdn = fit.ratio(0, 1)
        assert abs(Hn - G) < 5 * max(sdn, fit.std[0] / abs(fit.amp[1]))

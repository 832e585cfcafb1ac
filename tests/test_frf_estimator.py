"""The project's one FRF estimator (servo/frf/estimate.py) against independent
references: scipy.signal's csd/welch/coherence on the same settings, the average of
scipy's one-segment spectra where only some segments are used, and a known linear
system (scipy.signal.dlti).  ``servo diagnose``'s frequency path reads its response
through the same estimator (servo/diagnose/frf_modes.py ``measure``)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import signal

from servo.diagnose import frf_modes as fm
from servo.frf.estimate import (WelchSettings, coherence, equivalent_averages, estimate, h1, instrumental, psd,
                                segment_starts, spectra)  # fmt: skip

FS = 10_000.0
DT = 1 / FS
SYS = signal.dlti([0.02, 0.03], [1.0, -1.6, 0.8], dt=DT)  # a lightly damped resonance near 1 kHz


def _record(n=60_001, noise=0.05, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    _, y = signal.dlsim(SYS, u)
    return u, y.ravel() + noise * rng.standard_normal(n)


def _closed(n=60_001, seed=1):
    """``y = G u + n``, ``u = r - 0.5 y`` (a proportional loop, noise fed back): the
    instrument ``r`` is independent of ``n``."""
    rng = np.random.default_rng(seed)
    r = rng.standard_normal(n)
    e = 0.05 * rng.standard_normal(n)
    b, a = np.array([0.0, 0.02, 0.03]), np.array([1.0, -1.6, 0.8])  # SYS in powers of z^-1
    # y = G (r - k y) + e  ->  y = G/(1 + k G) r + 1/(1 + k G) e, as difference equations
    k = 0.5
    y = signal.lfilter(b, a + k * b, r) + signal.lfilter(a, a + k * b, e)
    return r, r - k * y, y


@pytest.mark.parametrize("nper,overlap,detrend", [(1024, 0.5, "constant"), (1000, 0.25, "linear"), (777, 0.6, "constant")])
def test_h1_and_coherence_are_scipys_on_the_same_settings(nper, overlap, detrend):
    u, y = _record()
    s = WelchSettings(nperseg=nper, overlap=overlap, detrend=detrend)
    est = h1(u, y, DT, s)
    kw = dict(fs=FS, window="hann", nperseg=nper, noverlap=int(round(overlap * nper)), detrend=detrend)
    f, Puy = signal.csd(u, y, **kw)
    _, Puu = signal.welch(u, **kw)
    _, g2 = signal.coherence(u, y, **kw)
    keep = f > 0
    assert np.array_equal(est.f_hz, f[keep])
    assert np.max(np.abs(est.H / (Puy / Puu)[keep] - 1)) < 1e-10
    assert np.max(np.abs(est.coherence - g2[keep])) < 1e-10
    # Bendat & Piersol eq. 9.90 from scipy's coherence and the Welch-1967 averages
    K = est.meta["segments"]
    K_eq = equivalent_averages(signal.get_window("hann", nper), nper, kw["noverlap"], K)
    ref = np.sqrt((1 - g2[keep]) / (2 * K_eq * g2[keep]))
    assert np.max(np.abs(est.rel_std / ref - 1)) < 1e-8


def test_instrumental_is_the_ratio_of_scipys_cross_spectra():
    r, u, y = _closed()
    s = WelchSettings(nperseg=1024)
    est = instrumental(r, u, y, DT, s)
    kw = dict(fs=FS, window="hann", nperseg=1024, noverlap=512)
    f, Pry = signal.csd(r, y, **kw)
    _, Pru = signal.csd(r, u, **kw)
    _, g2_ru = signal.coherence(r, u, **kw)
    keep = f > 0
    assert np.max(np.abs(est.H / (Pry / Pru)[keep] - 1)) < 1e-10
    assert np.max(np.abs(np.asarray(est.meta["coherence_ru"]) - g2_ru[keep])) < 1e-10


def test_the_estimates_recover_a_known_linear_system_within_their_bounds():
    """Open loop H1 and closed loop instrumental: |H - G| over (|G| rel_std) is Rayleigh
    with scale 1 where the coherence is high (its mean sqrt(pi/2) = 1.25)."""
    u, y = _record(200_001)
    r, uc, yc = _closed(200_001)
    for est in (h1(u, y, DT, WelchSettings(nperseg=512)), instrumental(r, uc, yc, DT, WelchSettings(nperseg=512))):
        G = SYS.freqresp(2 * np.pi * est.f_hz * DT)[1]
        ok = est.coherence > 0.8
        assert ok.sum() > 50
        z = np.abs(est.H - G)[ok] / (np.abs(G) * est.rel_std)[ok]
        assert 1.0 < np.mean(z) < 1.5
        assert np.mean(z > 3.03) < 0.03  # Rayleigh: P(z > 3.03) = 1 %


def test_a_subset_of_segments_is_the_mean_of_scipys_one_segment_spectra():
    """The segments ``servo diagnose`` keeps (those where the arm slides): the average of
    scipy's spectra of each kept segment alone; ``K_eq`` counts only the kept neighbours."""
    u, y = _record(20_000)
    s = WelchSettings(nperseg=1000).check(u.size)
    starts = segment_starts(u.size, 1000, 500)
    sel = starts[[0, 1, 2, 5, 9, 10, 20, 30]]
    sp = spectra({"u": u, "y": y}, DT, s, [("u", "y")], sel)
    kw = dict(fs=FS, window="hann", nperseg=1000, noverlap=0)
    Puy = np.mean([signal.csd(u[a : a + 1000], y[a : a + 1000], **kw)[1] for a in sel], axis=0)
    Puu = np.mean([signal.welch(u[a : a + 1000], **kw)[1] for a in sel], axis=0)
    assert np.max(np.abs(sp.P[("u", "y")] / Puy - 1)) < 1e-10
    assert np.max(np.abs(sp.P[("u", "u")] / Puu - 1)) < 1e-10
    w = signal.get_window("hann", 1000)
    rho = (np.sum(w[:500] * w[500:]) / np.sum(w**2)) ** 2
    assert sp.K == 8 and sp.K_eq == pytest.approx(8 / (1 + 2 * rho * 3 / 8), rel=1e-12)  # 3 adjacent pairs
    # all segments: the contiguous formula
    full = spectra({"u": u, "y": y}, DT, s, [("u", "y")], starts)
    assert full.K_eq == pytest.approx(equivalent_averages(w, 1000, 500, starts.size), rel=1e-12)


def test_diagnose_reads_its_response_through_the_same_estimator():
    """``frf_modes.measure`` is the estimator on the high-passed signals over the
    segments where the arm slides: with every sample moving, H1 and coherence are
    scipy's on those signals; segments that hold a stuck sample are left out."""
    u, y = _record(40_960)
    r = fm.measure(u, y, np.ones(u.size, bool), DT, 1024, 50.0)
    sos = signal.butter(4, 50.0 / (FS / 2), btype="high", output="sos")
    uf, yf = signal.sosfiltfilt(sos, u), signal.sosfiltfilt(sos, y)
    kw = dict(fs=FS, window="hann", nperseg=1024, noverlap=512)
    f, Puy = signal.csd(uf, yf, **kw)
    _, Puu = signal.welch(uf, **kw)
    _, g2 = signal.coherence(uf, yf, **kw)
    band = (f > 100) & (f < 0.45 * FS)
    assert np.max(np.abs(r.H[band] / (Puy / Puu)[band] - 1)) < 1e-10
    assert np.max(np.abs(r.coh[band] - g2[band])) < 1e-10
    moving = np.ones(u.size, bool)
    moving[5000:5100] = False  # stuck: the segments holding these samples go
    r2 = fm.measure(u, y, moving, DT, 1024, 50.0)
    starts = segment_starts(u.size, 1024, 512)
    kept = starts[~((starts < 5100) & (starts + 1024 > 5000))]
    sp = spectra({"u": uf, "x": yf}, DT, WelchSettings(nperseg=1024).check(u.size), [("u", "x")], kept)
    assert r2.K == kept.size == r.K - 2  # the two segments that hold samples 5000-5099
    assert np.allclose(r2.H[band], estimate(sp, "u", "x").H[band], rtol=1e-12, atol=0)


@pytest.mark.parametrize("n,nper,detrend", [(5000, 256, "constant"), (4097, 333, "none"), (300, 512, "constant"),
                                            (20_000, 16, "linear")])  # fmt: skip
def test_psd_and_coherence_are_scipys_welch_and_coherence_to_the_bit(n, nper, detrend):
    """The residual spectra of ``servo diagnose`` (locate, power band, plots) read the
    same estimator: scipy's numbers exactly, so that moving them here changed no
    diagnosis (a segment longer than the signal is shortened, as scipy does)."""
    rng = np.random.default_rng(n)
    a = np.cumsum(rng.standard_normal(n))
    b = signal.lfilter([0.3], [1, -0.5], a) + rng.standard_normal(n)
    fs = 1 / 2.1e-5  # 1/(1/fs) != fs: the sample rate is passed as the caller has it
    det = False if detrend == "none" else detrend
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # scipy: nperseg longer than the signal
        f0, P0 = signal.welch(a, fs, nperseg=nper, detrend=det)
        _, C0 = signal.coherence(a, b, fs, nperseg=nper, detrend=det)
    f, P = psd(a, fs, nper, detrend=detrend)
    _, C = coherence(a, b, fs, nper, detrend=detrend)
    assert np.array_equal(f, f0) and np.array_equal(P, P0) and np.array_equal(C, C0)


#: files outside servo/frf/ that may transform or correlate, and why (none estimates a
#: spectrum, a coherence or a frequency response)
ELSEWHERE = {
    "servo/scenarios/excitation.py": "synthesises a multisine (inverse FFT)",
    "servo/hdd/linsim.py": "applies a repeatable runout through a filter (FFT convolution)",
    "servo/hdd/pes.py": "streams the HDD benchmark's PES spectrum; servo.hdd sits below servo.frf in the layers",
    "servo/diagnose/select.py": "autocorrelation of a residual by FFT (a time-domain estimate)",
    "servo/diagnose/locate.py": "cross- and autocorrelation by FFT (time-domain estimates)",
    "studies/proving/cases.py": "the independent generator shapes pink noise and bounds a stroke by FFT; it "
                                "must not share code with the tool it measures",
}


def test_no_second_spectral_estimator_outside_the_one_home():
    """Welch spectra, coherences and FFTs live in servo/frf/ (estimate.py, sine.py);
    elsewhere only the uses listed in ``ELSEWHERE``."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    pattern = re.compile(r"np\.fft\.|numpy\.fft|scipy\.fft|from scipy import fft|signal\.(csd|welch|coherence|periodogram|"
                         r"spectrogram|ShortTimeFFT)|\bcsd\(|\bwelch\(")  # fmt: skip
    found = set()
    for path in list((root / "servo").rglob("*.py")) + list((root / "studies").rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel.startswith("servo/frf/"):
            continue
        if pattern.search(path.read_text()):
            found.add(rel)
    assert found <= set(ELSEWHERE), sorted(found - set(ELSEWHERE))
    # and one sine fit: the stepped-sine commands call the demodulator
    for rel in ("servo/loop/measure.py", "servo/experiments/bode.py"):
        text = (root / rel).read_text()
        assert "demodulate(" in text and "lstsq" not in text and "exp(-2j" not in text, rel

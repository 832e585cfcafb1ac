"""The rows' band chosen from where the input has power (issue 11.3): the power edge of
the measured motion, the decimation that covers it, bounded by what the reversals allow."""
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from servo.diagnose import power_band
from servo.diagnose.band import CANDIDATES, band_hz, choose
from servo.diagnose.concealed import concealed_recording
from servo.diagnose.job import Options, diagnose, prepare
import studies.proving.integrate as ig
from servo.identify.regressors import IdentificationError
from servo.io.recording import Recording


def _band_limited(n: int, fs: float, f_hi: float, seed: int, f_lo: float = 0.0) -> np.ndarray:
    """Unit-variance noise with power only within ``f_lo..f_hi`` Hz (an FFT brick wall)."""
    rng = np.random.default_rng(seed)
    X = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / fs)
    X[(f > f_hi) | (f < f_lo)] = 0
    s = np.fft.irfft(X, n)
    return s / s.std()


def _open_loop(fs: float, w: np.ndarray, noise: float = 1e-7, seed: int = 1) -> Recording:
    """An arm (J = 2, B = 5, Coulomb 0.5, K = 10, offset 0.1) driven open loop by the
    force ``w``, its position measured with white noise of std ``noise`` (the proving
    ground's integrator)."""
    n = w.size
    p = np.zeros(ig.N_PARAMS)
    p[ig.P_RATE], p[ig.P_J], p[ig.P_NSUB], p[ig.P_COG_PERIOD] = fs, 2.0, 4, 1.0
    p[ig.P_B], p[ig.P_FC], p[ig.P_FS], p[ig.P_VS] = 5.0, 0.5, 0.5, 1e-3
    p[ig.P_NOISE], p[ig.P_K], p[ig.P_H0] = noise, 10.0, 0.1
    rng = np.random.default_rng(seed)
    u, y, x = np.zeros(n), np.zeros(n), np.zeros(n)
    ig.run(p, np.zeros(n), np.ascontiguousarray(w), np.full(n, 1e30), np.ones(n), rng.standard_normal(n), np.zeros(1),
           np.ones(1), np.zeros(0), np.zeros(0), u, y, x, n)  # fmt: skip
    return Recording(np.arange(n) / fs, u, y, None, source="open loop")


def test_the_power_edge_is_where_the_motion_stands_over_the_noise():
    fs, n, sigma = 5000.0, 100_000, 1e-6
    for seed in range(3):  # the noise alone stands nowhere 20 dB over itself, at no frequency
        x = sigma * np.random.default_rng(seed).standard_normal(n)
        f, ratio = power_band.signal_to_noise(x, fs, sigma)
        assert power_band.edge_hz(x, fs, sigma) == 0.0
        assert 0.9 < np.median(ratio[1:]) < 1.1 and ratio.max() < 3.0
    motion = 1e-3 * _band_limited(n, fs, 300.0, 7)  # power up to 300 Hz, 60 dB over the noise
    x = motion + sigma * np.random.default_rng(9).standard_normal(n)
    bin_hz = fs / power_band.nperseg(n - 2)
    e = power_band.edge_hz(x, fs, sigma)  # a brick wall 60 dB tall, seen through Hann's 4-bin main lobe
    assert 300.0 - bin_hz <= e <= 300.0 + 4 * bin_hz
    # a plant's motion falls as 1/f^2 from a slow stroke: the window's leakage of the
    # stroke's power does not raise the edge (a Hann spectrum of x itself would)
    acc = _band_limited(n, fs, 100.0, 3, f_lo=0.5)
    x = signal.lfilter([1.0], [1.0, -2.0, 1.0], acc)  # a double integrator
    x = signal.detrend(x) * 1e-3 / np.std(signal.detrend(x)) + 1e-9 * np.random.default_rng(4).standard_normal(n)
    e = power_band.edge_hz(x, fs, 1e-9)
    assert 90.0 < e < 100.0 + 4 * bin_hz
    fx, Px = signal.welch(x, fs, nperseg=power_band.nperseg(n))
    assert fx[np.flatnonzero(Px > 100 * 2 * 1e-18 / fs)[-1]] > 1.3 * e  # the leakage the second difference avoids


def test_the_decimation_is_the_largest_whose_band_covers_the_edge():
    fs = 5000.0  # bands 200, 250, 333, 400, 500, 667 Hz for q = 10, 8, 6, 5, 4, 3
    assert power_band.decimation_for(150.0, fs, CANDIDATES) == 10
    assert power_band.decimation_for(200.0, fs, CANDIDATES) == 10
    assert power_band.decimation_for(201.0, fs, CANDIDATES) == 8
    assert power_band.decimation_for(300.0, fs, CANDIDATES) == 6
    assert power_band.decimation_for(2000.0, fs, CANDIDATES) == 3  # none covers it: the widest band


def test_a_recording_whose_input_has_power_up_to_a_known_frequency_gets_the_q_that_covers_it():
    fs, n = 5000.0, 40_000
    t = np.arange(n) / fs
    for f_hi, q in ((300.0, 6), (150.0, 10)):
        rec = _open_loop(fs, 3 * np.sin(2 * np.pi * 3 * t) + 2 * _band_limited(n, fs, f_hi, 2, 1.0))
        d, note = choose(rec, Options(band="power"), prepare)
        assert d.sig.settings.decimate == q, note
        edge = float(note.split("noise floor up to ")[1].split(" Hz")[0])
        assert 0.85 * f_hi < edge <= band_hz(d.sig.settings, fs), note
        assert note.startswith(f"decimation by {q}: the position stands 20 dB over its noise floor")
        assert "the motion reverses every" in note
        if q < 10:  # the band of the next larger decimation does not reach the edge
            assert band_hz(d.sig.settings, fs) * q / CANDIDATES[CANDIDATES.index(q) - 1] < edge
            # the default rule keeps the reversals' 10 and says where the power ends
            d0, note0 = choose(rec, Options(), prepare)
            assert d0.sig.settings.decimate == 10
            assert note0.endswith(f"beyond the band of 10 (200 Hz), within that of {q} "
                                  f"({band_hz(d.sig.settings, fs):.4g} Hz), which --decimate power would take")


def _fake_design(q: int, usable: float, noise_x: float, n: int):
    m = n // q
    valid = np.arange(m) < int(round(usable * m))
    vf = np.sin(2 * np.pi * np.arange(n) / 500.0)
    # usable_share: the chooser's share (the friction sign known on every valid row here)
    return SimpleNamespace(sig=SimpleNamespace(valid=valid, usable_share=float(valid.mean()), noise_x=noise_x, vf=vf,
                                               v_threshold=0.1, n=n,
                                               settings=SimpleNamespace(decimate=q)))  # fmt: skip


def test_the_reversals_bound_the_power_rule_never_the_other_way():
    """The rule on a ``prepare`` whose usable shares are set per decimation: a recording
    whose power the band of 10 covers gets the decimation the reversals allow; one whose
    power reaches further gets the smaller of the two, never one the reversals forbid."""
    fs, n = 5000.0, 40_000
    t = np.arange(n) / fs
    slow = Recording(t, np.sin(t), 1e-3 * np.sin(2 * np.pi * 5 * t), None, source="slow")  # no noise: edge fs/2
    shares = {10: 0.4, 8: 0.45, 6: 0.65, 5: 0.7, 4: 0.75, 3: 0.8}  # reversals forbid 10 and 8

    def prep(noise):
        return lambda rec, s, opt: _fake_design(s.decimate, shares[s.decimate], noise, n)

    # power inside the band of 10 (the motion stands over a noise of 1e-5 m only at 5 Hz)
    d, note = choose(slow, Options(band="power"), prep(1e-5))
    assert d.sig.settings.decimate == 6 and "inside the band of 10" in note and "by 10 only 40 %" in note
    assert choose(slow, Options(band="reversals"), prep(1e-5))[0].sig.settings.decimate == 6
    # power up to 300 Hz: 6 covers it and the reversals allow it
    wide = Recording(t, np.sin(t), slow.x + 1e-3 * _band_limited(n, fs, 300.0, 5), None, source="wide")
    assert choose(wide, Options(band="power"), prep(1e-7))[0].sig.settings.decimate == 6
    # power up to 450 Hz: 4 covers it (5 reaches 400 Hz)
    wider = Recording(t, np.sin(t), slow.x + 1e-3 * _band_limited(n, fs, 450.0, 5), None, source="wider")
    d, note = choose(wider, Options(band="power"), prep(1e-7))
    assert d.sig.settings.decimate == 4 and "beyond the band of 10 (200 Hz), within that of 4 (500 Hz)" in note
    with pytest.raises(IdentificationError, match="band rule"):
        choose(slow, Options(band="spectrum"), prep(1e-5))


@pytest.mark.slow
def test_where_the_band_of_10_covers_the_power_the_findings_are_the_old_ones():
    """A concealed Coulomb friction recording (the project's drive) whose motion stands
    over its noise inside the band of 10: the power rule keeps 10, and the diagnosis is
    the reversal rule's, finding for finding."""
    rec, _ = concealed_recording("coulomb_friction", 0.5, 3)
    new = diagnose(rec, Options(baseline="J,B,K,h0", band="power"))
    old = diagnose(rec, Options(baseline="J,B,K,h0", band="reversals"))
    assert new.sig.settings.decimate == old.sig.settings.decimate == 10
    assert "inside the band of 10" in new.band_note
    assert [f.physics for f in new.findings] == [f.physics for f in old.findings]
    assert "coulomb_friction" in [f.physics for f in new.findings]
    for a, b in zip(new.findings, old.findings):
        assert a.params == b.params
    assert new.verdict["verdict"] == old.verdict["verdict"]

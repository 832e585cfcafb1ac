"""Frequency responses from recordings, checked on linear systems whose response is
known exactly: a double integrator with a flexible mode (and a pivot's stiffness for the
open-loop record), sampled with a zero-order hold, recorded open loop and under a lead
controller with measurement noise fed back.  The estimate must lie within its own
coherence-based error bounds as often as those bounds promise (not more, not less), and
H1 on the closed-loop record must be caught out where the instrument is not."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from servo.cli import main
from servo.errors import RecordingError
from servo.frf.estimate import WelchSettings, default_nperseg, equivalent_averages, h1, instrumental, n_segments
from servo.io.frequency_response import FrequencyResponse, load_frequency_responses
from servo.io.recording import Recording, save_recording_csv

FS = 20_000.0
DT = 1 / FS
N = 2**18
F_MODE, ZETA_MODE, K_MODE = 1500.0, 0.05, 0.3 * (2 * np.pi * 100) ** 2


def _plant(pivot_hz: float | None):
    """ZOH-discretised ``g/(s^2 [+ 2 z w s + w^2]) + k_m/(s^2 + 2 z_m w_m s + w_m^2)``
    (m/A); ``g`` puts 0 dB at 100 Hz.  Returns (b, a) in powers of z^-1, same length."""
    g = (2 * np.pi * 100) ** 2
    wp = 0.0 if pivot_hz is None else 2 * np.pi * pivot_hz
    rigid = [1.0, 2 * 0.3 * wp, wp**2]
    wm = 2 * np.pi * F_MODE
    mode = [1.0, 2 * ZETA_MODE * wm, wm**2]
    num = np.polyadd(g * np.array(mode), K_MODE * np.array(rigid))
    den = np.polymul(rigid, mode)
    b, a, _ = signal.cont2discrete((num, den), DT, method="zoh")
    b = np.ravel(b)
    b = np.concatenate([np.zeros(a.size - b.size), b])
    return b / a[0], a / a[0]


def _true(b, a, f):
    return signal.freqz(b, a, worN=f, fs=FS)[1]


def _z_scores(est: FrequencyResponse, b, a):
    """``|H_est - H|/(|H| rel_std)``: Rayleigh-distributed with scale 1 if the bounds are right."""
    G = _true(b, a, est.f_hz)
    return np.abs(est.H - G) / (np.abs(G) * est.rel_std)


def _check_calibrated(est: FrequencyResponse, b, a, band, min_points: int):
    """Where the first-order bounds apply (coherence >= 0.5) they hold as promised:
    P(z > 1) = e^-0.5 = 61 %, P(z > 3) = 1.1 % (allowing for the correlation of
    neighbouring lines and the estimated coherence), and no gross outlier."""
    m = band & (est.coherence >= 0.5)
    z = _z_scores(est, b, a)[m]
    assert z.size >= min_points
    assert 0.45 < np.mean(z > 1) < 0.75  # not too loose, not too tight
    assert np.mean(z > 3) < 0.05
    assert z.max() < 6.0  # P(one of ~2000 Rayleigh draws > 6) = 3e-5


def open_loop_record(seed=0, noise=3e-4):
    """White current into the plant (with a 5 Hz pivot: an open-loop double integrator
    would drift away), white noise on the measured position."""
    rng = np.random.default_rng(seed)
    b, a = _plant(pivot_hz=5.0)
    u = rng.standard_normal(N)
    x = signal.lfilter(b, a, u) + noise * rng.standard_normal(N)
    return b, a, u, x


def closed_loop_record(seed=1, noise=1e-3):
    """A lead controller (crossover 150 Hz) holds the double integrator; the reference
    is white; the position is measured with white noise, which the loop feeds back."""
    rng = np.random.default_rng(seed)
    b, a = _plant(pivot_hz=None)
    wc = 2 * np.pi * 150
    g = (2 * np.pi * 100) ** 2
    kp = wc**2 / g / np.sqrt(3)  # |C G| = 1 at the crossover, 60 deg of lead
    cb, ca = signal.bilinear([kp / (wc / np.sqrt(3)), kp], [1 / (wc * np.sqrt(3)), 1], FS)
    cb = np.concatenate([np.zeros(ca.size - cb.size), cb])
    D = np.polyadd(np.convolve(ca, a), np.convolve(cb, b))
    assert np.max(np.abs(np.roots(D))) < 1  # the loop is stable
    r = rng.standard_normal(N) * 1e-2
    n = noise * rng.standard_normal(N)
    w = r - n
    u = signal.lfilter(np.convolve(cb, a), D, w)  # u = C/(1 + CG) (r - n)
    x = signal.lfilter(np.convolve(cb, b), D, w) + n  # measured y = G u + n
    return b, a, r, u, x, (cb, ca)


def test_welch_bookkeeping():
    assert n_segments(100, 20, 10) == 9
    nper = default_nperseg(N)
    assert nper == N // 8 and n_segments(N, nper, nper // 2) >= 8 and n_segments(N, 2 * nper, nper) < 8
    w = signal.get_window("hann", 1024)
    # Welch 1967: Hann at 50 % overlap, correlation 1/6 between neighbours -> rho = 1/36
    assert equivalent_averages(w, 1024, 512, 20) == pytest.approx(20 / (1 + 2 * (19 / 20) / 36), rel=1e-3)
    assert equivalent_averages(w, 1024, 0, 20) == 20


def test_h1_open_loop_matches_the_true_response_within_its_bounds():
    b, a, u, x = open_loop_record()
    est = h1(u, x, DT, WelchSettings(nperseg=8192), unit="m/A")
    _check_calibrated(est, b, a, est.f_hz > 20, 1500)
    # the coherence falls where the noise overtakes the falling response, and the
    # estimate is measured over more than two decades
    good = est.f_hz[(est.coherence > 0.9)]
    assert good.min() < 30 and good.max() > 2500
    assert est.coherence[est.f_hz > 9000].max() < 0.9
    # the mode is where it is: the peak of |H| f^2 (the rigid body's 1/f^2 taken out)
    # is the true response's, near the 1.5 kHz mode
    hi = (est.f_hz > 500) & (est.coherence > 0.9)
    f = est.f_hz[hi]
    peak, true_peak = (f[np.argmax(np.abs(H) * f**2)] for H in (est.H[hi], _true(b, a, f)))
    assert peak == pytest.approx(true_peak, abs=2 * est.meta["resolution_hz"])
    assert abs(true_peak - F_MODE) < 0.05 * F_MODE


def test_closed_loop_instrument_is_unbiased_where_h1_is_not():
    s = WelchSettings(nperseg=8192)
    b, a, r, u, x, _ = closed_loop_record(noise=1e-3)
    iv = instrumental(r, u, x, DT, s, unit="m/A")
    _check_calibrated(iv, b, a, iv.f_hz > 20, 200)
    assert "coherence_ru" in iv.meta and len(iv.meta["coherence_ru"]) == iv.f_hz.size
    # measurement noise as large as the reference: H1 converges to the loop's biased
    # value (G - q/C)/(1 + q), q = P_nn/P_rr = 1, not to G, and says it is coherent
    b, a, r, u, x, (cb, ca) = closed_loop_record(noise=1e-2)
    h = h1(u, x, DT, s, unit="m/A")
    iv = instrumental(r, u, x, DT, s, unit="m/A")
    _check_calibrated(iv, b, a, iv.f_hz > 20, 50)
    G = _true(b, a, h.f_hz)
    biased = (G - 1 / signal.freqz(cb, ca, worN=h.f_hz, fs=FS)[1]) / 2
    m = (h.f_hz > 100) & (h.f_hz < 300)
    assert np.median(h.coherence[m]) > 0.85
    z_true = np.abs(h.H - G) / (np.abs(G) * h.rel_std)
    z_biased = np.abs(h.H - biased) / (np.abs(biased) * h.rel_std)
    assert np.median(z_true[m]) > 8  # far outside its own bounds around the truth
    assert 0.45 < np.mean(z_biased[m] > 1) < 0.75 and np.mean(z_biased[m] > 3) < 0.05  # within them around the bias


@pytest.mark.slow
def test_frf_command_writes_loadable_files_and_converts_to_python_control(tmp_path, capsys):
    import control

    b, a, r, u, x, _ = closed_loop_record(seed=2)
    t = np.arange(N) * DT
    rec = tmp_path / "loop.csv"
    save_recording_csv(rec, Recording(t, u, x, None, r=r))
    out = tmp_path / "out"
    assert main(["frf", str(rec), "--closed-loop", "--nperseg", "8192", "--f-min", "20", "--f-max", "5000",
                 "--out", str(out)]) == 0  # fmt: skip
    text = capsys.readouterr().out
    assert "instrumental" in text and "coherence >= 0.9" in text
    assert {p.name for p in out.iterdir()} == {"frf.npz", "frf.csv", "frf.mat", "frf.h5", "frf.png", "report.html", "summary.json"}
    loaded = load_frequency_responses(out / "frf.npz")
    (label, resp), = loaded.items()
    assert label == "u -> x (instrument r)" and resp.unit == "m/A"
    assert resp.f_hz[0] >= 20 and resp.f_hz[-1] <= 5000
    _check_calibrated(resp, b, a, resp.f_hz > 0, 200)
    from_csv = load_frequency_responses(out / "frf.csv")[label]
    np.testing.assert_allclose(from_csv.H, resp.H, rtol=1e-9)
    np.testing.assert_allclose(from_csv.coherence, resp.coherence, rtol=1e-8)
    G = resp.to_control()
    assert isinstance(G, control.FrequencyResponseData)
    np.testing.assert_allclose(G.frequency_response(2 * np.pi * resp.f_hz[10:12]).complex.ravel(), resp.H[10:12])
    import json

    summary = json.loads((out / "summary.json").read_text())
    assert summary["welch"]["nperseg"] == 8192 and summary["coherent"]["points"] > 100


def test_frf_bad_input_is_one_line(tmp_path, capsys):
    t = np.arange(4000) * DT
    rec = tmp_path / "open.csv"
    save_recording_csv(rec, Recording(t, np.random.default_rng(0).standard_normal(t.size), np.sin(t)))
    const = tmp_path / "const.csv"
    save_recording_csv(const, Recording(t, np.ones(t.size), np.sin(t)))
    cases = [
        (["frf", str(rec), "--closed-loop"], "needs the reference"),
        (["frf", str(const)], "the input is constant"),
        (["frf", str(rec), "--nperseg", "5000"], "longer than the recording"),
        (["frf", str(rec), "--f-min", "50000"], "no frequency"),
        (["frf", str(rec), "--f-min", "-1"], "need 0 <= --f-min < --f-max"),
        (["frf", str(rec), "--f-min", "nan"], "need 0 <= --f-min < --f-max"),
        (["frf", str(rec), "--f-min", "10", "--f-max", "5"], "need 0 <= --f-min < --f-max"),
        (["frf", str(rec), "--window", "nosuch"], "window"),
    ]
    for argv, msg in cases:
        out = tmp_path / "o"
        assert main(argv + ["--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("servo: error: ") and msg in err and err.count("\n") == 1, err
        assert not out.exists()
    with pytest.raises(RecordingError):
        h1(np.zeros(100), np.ones(100), DT)

"""Track-following design (servo.design): crossover and margins on the double integrator,
notch depth, the benchmark's reference notches, the exact multirate loop, validation."""
import math

import control
import numpy as np
import pytest
from scipy import signal

from servo.design import Design, analog, discretise, loop, nss_reference, sections, track_following

J = 1e-3  # A*s^2/m
FS = 52800.0


@pytest.mark.parametrize("method", ["bilinear", "matched"])
@pytest.mark.parametrize("pes_every", [1, 2])
def test_designed_loop_has_requested_crossover_and_phase_margin(method, pes_every):
    fc, pm = 900.0, 40.0
    d = track_following(J, FS, fc, pm, integrator_ratio=5, notches=[(4100, 20, 0.4)], lowpass_hz=12000,
                        pes_every=pes_every, method=method, delay_s=10e-6)
    m = loop.margins(loop.open_loop(d, loop.double_integrator(J), 10e-6))
    assert m["stable"]
    assert m["crossovers_hz"] == pytest.approx([fc], rel=1e-6)  # one crossover, where asked
    assert m["phase_margin_deg"] == pytest.approx(pm, abs=0.05)
    assert m["gain_margin_db"] > 4.0


@pytest.mark.parametrize("method", ["bilinear", "matched", "zoh"])
def test_margins_agree_with_python_control_built_independently(method):
    """Single rate: the loop rebuilt with python-control alone (controller from the
    sections, plant by control.sample_system) gives the same margins."""
    d = track_following(J, 20000.0, 800.0, 45.0, integrator_ratio=4, method=method)
    T = 1 / d.fs
    C = control.tf([1.0], [1.0], T)
    for row in d.slow_sos:
        C = C * control.tf(row[:3], row[3:], T)
    P = control.sample_system(control.tf([1.0], [J, 0.0, 0.0]), T, "zoh")
    gm, pm, _, _, wgc, _ = control.stability_margins(C * P, returnall=True)
    mine = loop.margins(loop.open_loop(d, loop.double_integrator(J)))
    assert len(wgc) == 1 and wgc[0] / (2 * math.pi) == pytest.approx(800.0, rel=1e-3)
    assert pm[0] == pytest.approx(mine["phase_margin_deg"], abs=0.05) and pm[0] == pytest.approx(45.0, abs=0.1)
    upper = min(g for g in gm if g > 1)  # the lower one (< 1) is the integrator's, at low frequency
    lower = max(g for g in gm if g < 1)
    assert 20 * math.log10(upper) == pytest.approx(mine["gain_margin_upper_db"], abs=0.05)
    assert 20 * math.log10(lower) == pytest.approx(mine["gain_margin_lower_db"], abs=0.05)
    assert mine["gain_margin_db"] == min(mine["gain_margin_upper_db"], mine["gain_margin_lower_db"], key=abs)


def test_unreachable_phase_margin_is_an_error():
    with pytest.raises(ValueError, match="out of reach"):
        track_following(J, FS, 5000.0, 80.0, pes_every=2)


@pytest.mark.parametrize("method", ["bilinear", "matched"])
@pytest.mark.parametrize("f0,depth,width", [(4100, 20, 0.4), (12300, 15, 0.3), (16400, 10, 0.2)])
def test_notch_has_the_requested_depth_at_its_centre(method, f0, depth, width):
    s = discretise.sos(analog.notch(f0, depth, width), FS, method)
    h = sections.response(s, [f0, 1.0], FS)
    got = -20 * np.log10(abs(h[0]))
    if method == "bilinear":  # prewarped at the centre: exact
        assert got == pytest.approx(depth, abs=1e-6)
    else:  # exp-mapped zeros keep the centre; the depth moves with the frequency warping
        assert got == pytest.approx(depth, abs=1.5)
    assert abs(h[1]) == pytest.approx(1.0, abs=1e-3)  # unity at DC


@pytest.mark.parametrize("f0,gain,width,phase", [(120, 20, 0.01, 0), (900, 6, 0.4, 40), (5000, 3, 0.02, -30)])
def test_peak_has_the_requested_gain_and_phase_at_its_centre(f0, gain, width, phase):
    """``1 + k*e^(j*phi)`` at the centre (bilinear, prewarped there: exactly); far below it
    ``1 - width*k*sin(phi)``, far above it 1; its poles are the resonance's (``zeta = width/2``)."""
    fs = FS / 2
    b = analog.peak(f0, gain, width, phase)
    k = 10 ** (gain / 20) - 1
    assert b.response(f0) == pytest.approx(1 + k * np.exp(1j * math.radians(phase)), rel=1e-12)
    s = discretise.sos(b, fs, "bilinear")
    h = sections.response(s, [f0, f0 / 30, 30 * f0], fs)
    assert h[0] == pytest.approx(1 + k * np.exp(1j * math.radians(phase)), rel=1e-9)
    assert abs(h[1] - (1 - width * k * math.sin(math.radians(phase)))) < 0.1
    assert abs(h[2] - 1) < 0.1 or 30 * f0 > fs / 2  # (above the PES Nyquist frequency: no such point)
    assert np.abs(sections.poles(s)) == pytest.approx(np.exp(-width / 2 * 2 * math.pi * f0 / fs), rel=5e-3)  # (warped)
    with pytest.raises(ValueError, match="peak"):
        analog.peak(f0, gain, width, 120.0)


def test_peak_filters_lower_the_sensitivity_at_their_harmonics():
    """Peaks at the spindle harmonics (phase-stable: T is near 1 there) lower |S| there by
    about ``|1 + T*P|``, and the lead is solved with them in place: the crossover and the
    phase margin stay where asked."""
    h = [120.0, 240.0, 360.0]
    peaks = [(f, 20.0, 0.01, 0.0) for f in h]
    kw = dict(integrator_ratio=8, notches=[(4100, 15, 0.4)], pes_every=2, delay_s=10e-6)
    plain = track_following(J, FS, 950.0, 44.0, **kw)
    peaked = track_following(J, FS, 950.0, 44.0, peaks=peaks, **kw)
    assert peaked.slow_sos.shape == (4, 6) and peaked.info["peaks"] == [list(p) for p in peaks]
    plant = loop.double_integrator(J)
    ms = [loop.margins(loop.open_loop(d, plant, 10e-6)) for d in (plain, peaked)]
    for m in ms:
        assert m["stable"] and m["crossover_hz"] == pytest.approx(950.0, rel=1e-6)
        assert m["phase_margin_deg"] == pytest.approx(44.0, abs=0.05)
    S = [np.abs(1 / (1 + loop.frequency_response(loop.open_loop(d, plant, 10e-6), h))) for d in (plain, peaked)]
    assert np.all(S[1] < S[0] / 8)  # 20 dB of peak gain: 10x where T is near 1


def test_zoh_design_keeps_its_notches_deep():
    s = discretise.sos(analog.notch(4100, 20, 0.4), FS, "zoh")
    assert -20 * np.log10(abs(sections.response(s, 4100.0, FS))) < 15  # a hold equivalent loses the zeros
    d = track_following(J, FS, 800, 40, notches=[(4100, 20, 0.4)], method="zoh")
    assert -20 * np.log10(abs(d.fast_response(4100.0))) == pytest.approx(20, abs=1.5)


# the benchmark's notch matrices (example1/followdemo.m), at Ts/2: (A row 1, B0, C, D)
NSS_SS = {
    4100: ([1.606, -0.8177], 0.935, [-0.1059, 0.1206], 0.935),
    5000: ([1.533, -0.8506], 0.9308, [-0.1097, 0.1333], 0.9308),
    8200: ([0.8627, -0.4936], 0.7434, [-0.2204, 0.4382], 0.7434),
    12300: ([0.2247, -0.4117], 0.6945, [0.01887, 0.5033], 0.6945),
}


def test_reference_notches_reproduce_the_benchmark_matrices():
    Ts = 60 / 7200 / 220
    d = nss_reference(1 / Ts)
    f = np.linspace(100, 1 / Ts - 100, 400)
    for row, (f0, (a, b0, c, dd)) in zip(d.fast_sos, NSS_SS.items()):
        A = np.array([a, [1.0, 0.0]])
        num, den = signal.ss2tf(A, [[b0], [0.0]], [c], [[dd]])
        _, h_ref = signal.freqz(num[0], den, worN=f, fs=2 / Ts)
        h = sections.response(row, f, 2 / Ts)
        assert np.max(np.abs(h - h_ref)) < 5e-3, f0  # the matrices have 4 digits


def test_reference_pid_is_the_benchmark_formula():
    Ts = 60 / 7200 / 220
    d = nss_reference(1 / Ts)
    P, I, D, g, Tp = 2, 0.05, 70, 1.665e3, 2.54e-7
    f = np.array([10.0, 120.0, 1000.0, 5000.0])
    zi = np.exp(-2j * np.pi * f * Ts)
    c = (P * (1 - zi) + I * zi + D * (1 - zi) ** 2) / (1 - zi) / (g * Tp)
    assert np.allclose(d.slow_response(f), c, rtol=1e-12)
    assert d.pes_every == 2 and d.fs == pytest.approx(2 / Ts)


def test_lifted_plant_matches_brute_force_multirate_simulation():
    """The hold + fast cascade + ZOH plant with a fractional delay + PES sampling, lifted
    to the PES rate, against stepping the same chain tick by tick."""
    d = nss_reference(26400.0)  # pes_every = 2, four notches at 52.8 kHz
    w0, z0 = 2 * np.pi * 3000, 0.05  # a stable plant, current -> m
    A = np.array([[0, 1], [-w0 * w0, -2 * z0 * w0]])
    B, C = np.array([[0.0], [1e3]]), np.array([[1.0, 0.0]])
    delay = 2.375 / d.fs  # two whole ticks and a fraction (on the fine grid below)
    Ls = loop.plant_after_controller(d, (A, B, C), delay)
    v = np.random.default_rng(3).standard_normal(400)
    # brute force at the tick rate: hold, fast cascade, plant with delay (finely integrated)
    u = signal.sosfilt(d.fast_sos, np.repeat(v, 2))
    Af, Bf, Cf, Df = loop.zoh_delay(A, B, C, 1 / d.fs, delay)
    x = np.zeros(Af.shape[0])
    y = []
    for k, uk in enumerate(u):
        if k % 2 == 0:
            y.append(Cf @ x)
        x = Af @ x + Bf[:, 0] * uk
    # the same delay by an independent route: continuous simulation with scipy lsim
    t = np.arange(u.shape[0] * 40) / (40 * d.fs)
    uu = np.repeat(u, 40)
    shift = int(round(delay * 40 * d.fs))
    uu = np.concatenate([np.zeros(shift), uu[:-shift]])
    _, yc, _ = signal.lsim((A, B, C, [[0.0]]), uu, t, interp=False)
    yc = yc[:: 80]
    x = np.zeros(Ls[0].shape[0])
    ys = []
    for vk in v:
        ys.append((Ls[2] @ x)[0])
        x = Ls[0] @ x + Ls[1][:, 0] * vk
    ys = np.array(ys)
    assert np.allclose(ys, np.ravel(y), atol=1e-9 * np.max(np.abs(ys)))
    assert np.allclose(ys, yc, atol=2e-3 * np.max(np.abs(ys)))


def test_response_approximation_is_exact_single_rate_and_close_multirate():
    d1 = track_following(J, FS, 1000, 40, notches=[(7000, 20, 0.4)], pes_every=1)
    f = np.array([100.0, 1000.0])
    direct = d1.slow_response(f) * d1.fast_response(f)
    assert np.allclose(d1.response(f), direct)
    d2 = track_following(J, FS, 1000, 40, notches=[(7000, 20, 0.4)], pes_every=2)
    # the hold's fundamental: magnitude cos(pi f/fs), half-tick delay
    h = d2.hold_response(f)
    assert np.allclose(np.abs(h), np.cos(np.pi * f / FS)) and np.allclose(np.angle(h), -np.pi * f / FS)


def test_pid_form_of_the_lead_integrator_is_the_same_transfer_function():
    b = analog.lead_integrator(1000.0, 9.0, 5.0, 2.5)
    p = b.params
    f = np.array([10.0, 300.0, 1000.0, 8000.0])
    s = 2j * np.pi * f
    pid = p["kp"] + p["ki"] / s + p["kd"] * s / (1 + s / (2 * np.pi * p["derivative_filter_hz"]))
    assert np.allclose(b.response(f), pid, rtol=1e-12)


def test_design_rejects_long_or_unstable_cascades():
    good = np.array([[1.0, 0, 0, 1.0, -0.5, 0]])
    with pytest.raises(ValueError, match="more than 8"):
        Design(good, np.repeat(good, 9, axis=0), FS)
    with pytest.raises(ValueError, match="not strictly inside"):
        Design(good, np.array([[1.0, 0, 0, 1.0, -2.0, 1.0]]), FS)  # double pole at z = 1
    with pytest.raises(ValueError, match="not strictly inside"):
        Design(np.array([[1.0, 0, 0, 1.0, -1.0, 0]]), good, FS)  # an integrator not declared
    d = Design(np.array([[1.0, 0, 0, 1.0, -1.0, 0]]), good, FS, integrators=1)
    assert d.slow_sos.flags["C_CONTIGUOUS"] and d.slow_sos.dtype == np.float64
    with pytest.raises(ValueError, match="at or above Nyquist"):
        track_following(J, FS, 1000, 40, notches=[(30000, 20, 0.4)])

"""One margins() (servo.design.margins), cross-checked against python-control.

For every controller kind the loop is built a second way with python-control (the
controller as transfer functions from its own formula or sections, the plant sampled by
``control.sample_system``), and every number of :func:`servo.design.margins.margins` is
checked against ``control.stability_margins`` of python-control's own frequency response
over the whole band: every gain crossover and its phase margin (1 deg), every phase
crossover and its gain margin (0.2 dB), the delay margin, and the peaks of |S| and |T|."""
import math
import warnings

import control
import numpy as np
import pytest

from servo.config import Config
from servo.controllers import get_kind
from servo.design import loop
from servo.design.margins import MARGIN_KEYS, margins
from servo.hdd import designs
from servo.hdd.benchmark import benchmark
from servo.hdd.plant import plants
from servo.loop.job import design_margins

TICK = 2e-5  # the default run's tick (50 kHz)


def python_control(L, points: int = 8000) -> dict:
    """``control.stability_margins`` of python-control's own frequency response of ``L``
    (a :class:`control.FrequencyResponseData` on ``points`` log-spaced frequencies from
    5 Hz to Nyquist; its polynomial method, on loops of this order, misplaces crossings
    by up to 20 Hz and reports spurious ones), crossings in Hz."""
    nyq = math.pi / L.dt
    w = np.geomspace(2 * math.pi * 5.0, nyq, points)
    frd = control.frd(L, w)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gm, pm, sm, wpc, wgc, wms = control.stability_margins(frd, returnall=True)
    gc = {float(w_ / (2 * math.pi)): float(p) for w_, p in zip(np.atleast_1d(wgc), np.atleast_1d(pm)) if 0 < w_ <= nyq}
    pc = {float(w_ / (2 * math.pi)): 20 * math.log10(g) for w_, g in zip(np.atleast_1d(wpc), np.atleast_1d(gm))
          if 0 < w_ <= nyq}  # fmt: skip
    h = np.asarray(frd.complex).ravel()
    return dict(gc=gc, pc=pc, max_S_db=float(-20 * np.log10(np.abs(1 + h).min())),
                max_T_db=float(20 * np.log10(np.abs(h / (1 + h)).max())),
                sm_db=float(-20 * np.log10(np.min(sm))) if np.size(sm) else -math.inf)  # fmt: skip


def assert_agree(mine: dict, ref: dict, dt: float = TICK) -> None:
    assert mine["stable"] is True
    # every gain crossover, both ways
    assert len(mine["crossovers_hz"]) == len(ref["gc"]), (mine["crossovers_hz"], ref["gc"])
    for f, p in zip(mine["crossovers_hz"], mine["phase_margins_deg"]):
        (fr, pr), = [(k, v) for k, v in ref["gc"].items() if abs(k / f - 1) < 1e-3]
        assert abs((p - pr + 180) % 360 - 180) < 1.0, (f, p, pr)
    assert mine["crossover_hz"] == min(mine["crossovers_hz"])  # the lowest crossing is the servo crossover
    # every phase crossover (mine may add the Nyquist frequency, where L is real)
    nyq = 0.5 / dt
    inner = [g for g in mine["gain_margins"] if g["hz"] < 0.999 * nyq]
    assert len(inner) == len([k for k in ref["pc"] if k < 0.999 * nyq]), (mine["gain_margins"], ref["pc"])
    for g in inner:
        (gr,) = [v for k, v in ref["pc"].items() if abs(k / g["hz"] - 1) < 1e-3]
        assert abs(g["db"] - gr) < 0.2, (g, gr)
        assert g["side"] == ("upper" if gr > 0 else "lower")
    b = [g for g in mine["gain_margins"] if g["binding"]]
    assert len(b) == 1 and b[0]["db"] == mine["gain_margin_db"] == min((g["db"] for g in mine["gain_margins"]), key=abs)
    # the delay margin from python-control's phase margins
    dm = min((p % 360) / (360 * f) for f, p in ref["gc"].items())
    assert mine["delay_margin_s"] == pytest.approx(dm, rel=1e-3)
    # the peaks, over the whole band
    assert abs(mine["max_S_db"] - ref["max_S_db"]) < 0.2 and mine["max_S_db"] >= ref["sm_db"] - 0.01
    assert abs(mine["max_T_db"] - ref["max_T_db"]) < 0.2


def sos_tf(sos, dt):
    out = control.tf([1.0], [1.0], dt)
    for row in np.asarray(sos).reshape(-1, 6):
        out = out * control.tf(np.trim_zeros(row[:3], "b"), np.trim_zeros(row[3:], "b"), dt)
    return out


def drive_tf(cfg: Config, dt: float):
    """The drive's linear model, compensated (rigid body ``1/(J s^2)`` plus the flexible
    modes), zero-order hold at ``dt`` and a one-tick input delay, by python-control."""
    d = cfg.drive
    G = control.ss([[0, 1], [0, 0]], [[0], [1 / d.J]], [[1, 0]], 0)
    for f, z, g in zip(d.mode_hz, d.mode_zeta, d.mode_gain):  # in parallel, as state space (no polynomials)
        w = 2 * math.pi * f
        G = control.parallel(G, control.ss([[0, 1], [-w * w, -2 * z * w]], [[0], [1 / d.J]], [[g, 0]], 0))
    return control.sample_system(G, dt, "zoh") * control.tf([1.0], [1.0, 0.0], dt)


@pytest.mark.slow
def test_the_pi_kinds_margins_agree_with_python_control():
    cfg = Config().replace(drive={"input_delay_s": TICK}, controller={"velocity_source": "estimated"})
    pi, c = cfg.controller.section, cfg.controller
    zi = control.tf([1.0], [1.0, 0.0], TICK)
    a = math.exp(-2 * math.pi * c.velocity_cutoff_hz * TICK)
    C = pi.kp + pi.ki * TICK * zi / (1 - zi) + pi.kd * (1 - a) * (1 - zi) / TICK / (1 - a * zi)
    mine = design_margins(cfg, "drive")
    assert_agree(mine, python_control(control.ss(C) * drive_tf(cfg, TICK)))
    assert mine["gain_margin_upper_db"] > 0 and mine["gain_margin_lower_db"] < -10  # a margin on each side


@pytest.mark.slow
def test_the_track_kinds_margins_agree_with_python_control():
    cfg = Config().replace(drive={"input_delay_s": TICK}, controller={"kind": "track"})
    d = get_kind("track").designed(cfg.controller.section, cfg)
    assert d.pes_every == 1
    C = sos_tf(d.slow_sos, TICK) * sos_tf(d.fast_sos, TICK)
    assert_agree(design_margins(cfg, "drive"), python_control(C * drive_tf(cfg, TICK)))


@pytest.mark.slow
@pytest.mark.parametrize("design", ["reference", "own"])
def test_the_benchmark_loops_margins_agree_with_python_control(design):
    """The nss kind's design (the benchmark's reference) and the project's track design on
    the benchmark's nominal plant, the exact multirate loop lifted to the PES rate."""
    b = benchmark(2)
    d = designs.reference(2) if design == "reference" else designs.own(2)
    L = loop.open_loop(d, plants(b)[0][1], b.Td)
    assert_agree(loop.margins(L), python_control(L), b.Ts)


def test_the_default_pi_loops_binding_margin_is_the_upper_one():
    """The default loop (measured velocity, 10 us delay): the 7 kHz mode sets the upper
    gain margin (4.26 dB, the gain may grow 1.63x) and the peak of |S|, above any band a
    20-2000 Hz search sees; the integrator's lower margin is -16.8 dB."""
    m = design_margins(Config(), "drive")
    assert m["gain_margin_side"] == "upper" and m["gain_margin_db"] == pytest.approx(4.26, abs=0.02)
    assert 6800 < m["gain_margin_hz"] < 7000 and m["gain_margin_lower_db"] == pytest.approx(-16.81, abs=0.02)
    assert m["max_S_db"] == pytest.approx(10.29, abs=0.02) and 6800 < m["max_S_hz"] < 7000
    assert m["crossover_hz"] == pytest.approx(147.5, abs=0.5) and m["crossover_hz"] == min(m["crossovers_hz"])


def test_an_unstable_loop_has_no_margins():
    cfg = Config()
    pi = cfg.controller.section
    hot = cfg.replace(controller={"pi": {"kp": 1.7 * pi.kp, "ki": 1.7 * pi.ki, "kd": 1.7 * pi.kd}})
    assert design_margins(cfg.replace(controller={"pi": {"kp": 1.6 * pi.kp, "ki": 1.6 * pi.ki,
                                                          "kd": 1.6 * pi.kd}}), "drive")["stable"] is True  # fmt: skip
    m = design_margins(hot, "drive")  # the upper gain margin is 4.26 dB = 1.63x
    assert m["stable"] is False and m["unstable_poles"] == 2
    assert all(m[k] is None for k in MARGIN_KEYS) and m["gain_margins"] == []
    # a system: its pole radius; the benchmark's PID with 20 dB / 0.3 notches on P16 K+10 %
    from servo.design import nss_reference

    b = benchmark(2)
    d = nss_reference(1 / b.Ts, notch_depth_db=(20,) * 4, notch_width=(0.3,) * 4)
    (p,) = [p for name, p in plants(b) if name == "P16 K+10%"]
    m = loop.margins(loop.open_loop(d, p, b.Td), n=2000)
    assert m["stable"] is False and 1.0 < m["pole_radius"] < 1.001
    assert all(m[k] is None for k in MARGIN_KEYS)


def test_the_nyquist_count_matches_the_poles():
    """The Nyquist criterion of frequency data against the closed-loop poles of the same
    loop as a system, over gains that cross both gain margins."""
    b = benchmark(2)
    d = designs.reference(2)
    L0 = loop.open_loop(d, plants(b)[0][1], b.Td)
    fn = 0.5 / b.Ts
    f = np.geomspace(fn * 1e-5, fn, 20000)
    h = loop.frequency_response(L0, f)
    for k in (0.05, 1.0, 1.7, 2.0, 8.0):
        poles = control.feedback(k * L0, 1).poles()
        m = margins(f, k * h, dense=True, nyquist_hz=fn)
        assert m["unstable_poles"] == int(np.sum(np.abs(poles) > 1)), k

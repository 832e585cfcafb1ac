"""A measured loop knows how well its margins are known (servo/loop/quality.py): the
uncertainty of every margin from the points' own random error, and a warning beyond
tolerance."""
import math

import control
import numpy as np
import pytest

from servo.design.margins import margins
from servo.loop.quality import TOLERANCE, uncertainty, warnings_for


def loop():
    s = control.tf("s")
    L = 40 * (s + 3) / (s * s * (s / 30 + 1) * (s / 80 + 1))
    f = np.geomspace(0.1, 30.0, 25)
    return f, np.asarray(L(2j * np.pi * f))


def test_margin_uncertainty_follows_the_points_error():
    f, L = loop()
    m = margins(f, L)
    u = uncertainty(m, f, L, np.full(f.shape, 0.01))
    assert u["phase_margin_deg"] == pytest.approx(math.degrees(0.01), rel=1e-9)
    assert u["gain_margin_db"] == pytest.approx(20 / math.log(10) * 0.01, rel=1e-9)
    # the crossover: e / |slope of ln|L| in ln f| (about 1.2 near crossover here)
    assert 0.005 * m["crossover_hz"] < u["crossover_hz"] < 0.012 * m["crossover_hz"]
    assert 0 < u["max_S_db"] < 20 / math.log(10) * 0.01 * (10 ** (m["max_S_db"] / 20) + 1)  # |T| <= |S| + 1
    assert warnings_for("x", m, u) == []
    noisy = uncertainty(m, f, L, np.full(f.shape, 0.2))  # 11 deg of phase
    w = warnings_for("measured, on", m, noisy)
    assert {line.split(" = ")[0] for line in w} == {f"measured, on: {k}" for k in TOLERANCE}
    assert all("raise --levels" in line for line in w)


def test_unknown_error_gives_no_uncertainty_and_no_warning():
    f, L = loop()
    m = margins(f, L)
    u = uncertainty(m, f, L, np.full(f.shape, np.nan))
    assert all(v is None for v in u.values()) and warnings_for("x", m, u) == []


def test_an_adapted_excitation_reaches_the_target_error():
    """On the default drive with 20 nm sensor noise a fixed 0.2 mA leaves the top
    frequencies' L uncertain by 15 %; adapted to 2 % (capped at 20 mA) every frequency is
    within a factor 2.5 of the target, inside the bounds."""
    from servo.config import Config
    from servo.loop.measure import STROKE_SHARE, LoopSettings, _bounds, measure, program

    cfg = Config().replace(drive={"position_noise": 20e-9})
    band = dict(f_min=20.0, f_max=2000.0, n_freq=14, periods=4, settle_periods=3, settle_s=0.01)
    fixed = measure(cfg, LoopSettings(**band, levels=(0.2e-3,)), 0.2e-3, True)
    assert np.max(fixed.response("L").rel_std) > 0.1
    s = LoopSettings(**band, levels=(20e-3,), target_rel_err=0.02)
    m = measure(cfg, s, 20e-3, True)
    rel = m.response("L").rel_std
    assert np.all(rel < 2.5 * 0.02) and abs(np.median(rel) / 0.02 - 1) < 0.25, rel
    assert np.all(m.levels_A <= _bounds(cfg, program(cfg, s), 20e-3, True) * (1 + 1e-12)) and m.clipped == 0
    assert STROKE_SHARE == 0.01 and "adapted to 2 %" in m.label


def test_the_hdd_example_is_measured_against_its_noise(tmp_path):
    """docs/hdd.md's recipe: examples/hdd-nss-v2.toml (3.81 nm sensor noise) measured with
    an excitation adapted to 2 % gives the design's crossover, phase and gain margins and
    max|S| (at the former fixed 0.2 mA it reported 1180 Hz and 2.6 dB from noise)."""
    from pathlib import Path

    from servo.config import load_config
    from servo.loop.job import run_loop
    from servo.loop.measure import LoopSettings

    cfg = load_config(Path(__file__).resolve().parents[1] / "examples" / "hdd-nss-v2.toml")
    s = LoopSettings(f_min=300.0, f_max=4000.0, n_freq=14, levels=(50e-3,), target_rel_err=0.02)
    summary = run_loop(cfg, tmp_path / "out", s, "off")
    got, want = summary["runs"][0]["margins"], summary["designs"]["drive model, pivot small-signal, no comp."]
    assert abs(got["crossover_hz"] / want["crossover_hz"] - 1) < 0.01
    assert abs(got["phase_margin_deg"] - want["phase_margin_deg"]) < 1.0
    assert abs(got["gain_margin_db"] - want["gain_margin_db"]) < 0.3 and got["gain_margin_side"] == "upper"
    assert abs(got["max_S_db"] - want["max_S_db"]) < 0.3

"""The input dead zone (``servo/physics/dead_zone.py``) end to end: the simulated drive
carries it, the concealed study hides it and ``servo diagnose`` names and fits it with
the held-out proof (on the concealed study's recording and on the independent
generator's), ``servo compensate`` cancels it with the inverse dead zone, checked in
closed loop."""
import json
import math

import numpy as np
import pytest

from kernels.cancel import dead_zone_inverse
from kernels.plant import dead_zone
from servo.compensate.job import compensate, recommend
from servo.compensate.propose import apply
from servo.config import Config, to_toml
from servo.diagnose.concealed import EFFECTS, concealed_recording
from servo.diagnose.job import Options, diagnose
from servo.diagnose.report import build_report
from servo.runtime.controller import stage_params
from studies.proving import cases
from tests.helpers import NO_MODES, quiet_config, simulate_open_loop
from tests.test_compensate import LARGE
from tests.test_compensation import acceleration_error, drive_open_loop_cfg

W = 2e-3  # A


def test_the_drive_gets_the_command_less_the_half_width():
    """A drive with a dead zone of half-width W under any command moves exactly as the
    same drive without one under ``sgn(u)*max(|u| - W, 0)``, to the bit; within the band
    the arm moves as under no command at all (its bias and spring alone)."""
    rng = np.random.default_rng(4)
    u = np.concatenate([np.full(500, 0.9 * W), np.full(500, -0.9 * W), 6e-3 * rng.standard_normal(2000)])
    cfg = quiet_config(**NO_MODES, dead_zone=W)
    out, _ = simulate_open_loop(cfg, u)
    ref, _ = simulate_open_loop(quiet_config(**NO_MODES), u - np.clip(u, -W, W))
    assert np.array_equal(out, ref)
    idle, _ = simulate_open_loop(quiet_config(**NO_MODES), np.zeros(1000))
    assert np.array_equal(out[:, :1001], idle)
    free, _ = simulate_open_loop(quiet_config(**NO_MODES), u)
    assert np.abs(out[0] - free[0]).max() > 1e-5  # the band changed the motion


@pytest.mark.parametrize("u", [-3e-3, -2e-3 - 1e-12, -1e-9, 0.0, 1e-9, 2.5e-3, 0.5])
def test_the_inverse_dead_zone_gives_back_the_command(u):
    assert dead_zone(dead_zone_inverse(u, W), W) == pytest.approx(u, abs=1e-18)


def test_the_inverse_is_bounded_by_the_authority():
    c = Config()
    assert stage_params(c)["dz_w"][0] == 0.0  # off by default
    assert stage_params(c.replace(compensator={"dead_zone": W}))["dz_w"][0] == W
    assert stage_params(c.replace(compensator={"dead_zone": W, "authority": 5e-4}))["dz_w"][0] == 5e-4


def _named(D, truth_width, tol, output=True):
    names = [f.physics for f in D.findings]
    assert names and names[0] == "dead_zone", [(f.physics, f.params) for f in D.findings]
    f = D.findings[0]
    assert f.params["width"] == pytest.approx(truth_width, rel=tol)
    # the held-out proof: the force error (and the output prediction) improve on the held-out part
    assert f.after["force_rel_pct"] < f.before["force_rel_pct"]
    if output:
        assert f.after["output_nrmse"] < f.before["output_nrmse"]
    assert D.verdict["verdict"] == "explained"


@pytest.fixture(scope="module")
def concealed():
    e = EFFECTS["dead_zone"]
    rec, truth = concealed_recording("dead_zone", e.clear, seed=11)
    return rec, truth, diagnose(rec, Options(baseline=truth["baseline"]))


def test_a_concealed_dead_zone_is_named_and_fitted(concealed):
    rec, truth, D = concealed
    _named(D, truth["drive"]["dead_zone"], 0.05)


@pytest.mark.parametrize("loop", ["pdi", "force"])
def test_the_independent_generators_dead_zone_is_named_and_fitted(loop):
    """The proving ground's ``dead_zone`` family (half-width = Fc of its drive), in a
    closed loop and under a force drive: named, fitted within 15 % (the force drive's
    fit is the looser: 11 % on this seed) and proved on the held-out force error.  Under
    the force drive the short-horizon output prediction is not better with the term
    (0.02689 against 0.02687 on this seed): it is not asserted there."""
    rec, truth = cases.recording(cases.Case("dead_zone", 1.0, loop, "prbs", 5000.0, 20000), seed=1)
    assert truth["verdicts"] == ["explained"]  # the vocabulary has the term
    _named(diagnose(rec), truth["Fc"], 0.15, output=loop == "pdi")


def test_compensate_proposes_the_inverse_and_its_closed_loop_check_chooses_it(concealed, tmp_path):
    """The diagnosis's report, compensated on the drive it came from: the proposal holds
    the inverse dead zone at the fitted half-width, the closed-loop check chooses it over
    eq. 9 alone (on the model's closed loop, :mod:`servo.compensate.check`)."""
    rec, truth, D = concealed
    path = tmp_path / "report.json"
    path.write_text(json.dumps(build_report(D)))
    base = Config().replace(drive=truth["drive"], run={"sample_rate_hz": 50_000.0})
    r = recommend(path, base)
    assert r.proposal.section["dead_zone"] == pytest.approx(truth["drive"]["dead_zone"], rel=0.05)
    assert "input dead zone (its inverse on the command)" in [t.name for t in r.proposal.cancelled]
    assert r.check is not None and r.check.chosen == "augmented", r.check.why
    assert r.proposal.section["authority"] > r.proposal.section["dead_zone"]  # the inverse is not cut short


def test_the_inverse_restores_the_double_integrator(tmp_path):
    """The default drive (its Dahl pivot, which eq. 9 cancels) with a dead zone of 0.5 mA,
    compensated from its own config: the plant the controller sees (its gains at 0, an
    excitation as ``u_n``) is the double integrator of eq. (10) with the inverse, and is
    not without it (eq. 9's compensator of the same drive)."""
    cfg = quiet_config(**NO_MODES, input_delay_s=0.0, dead_zone=5e-4).replace(
        controller={"pi": dict(kp=0.0, ki=0.0, kd=0.0)})  # fmt: skip
    path = tmp_path / "drive.toml"
    path.write_text(to_toml(cfg))
    err = {}
    for name, paper in (("augmented", False), ("eq. 9", True)):
        p = compensate(path, cfg, paper=paper)
        assert ("dead_zone" in p.section) == (not paper)
        xs, un = drive_open_loop_cfg(apply(cfg, p), LARGE)
        err[name] = acceleration_error(xs, un, cfg)
    assert err["augmented"] < 0.01 and err["eq. 9"] > 0.05, err

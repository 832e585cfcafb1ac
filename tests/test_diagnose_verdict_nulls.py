"""Null recordings read `consistent` where two checks misread noise (docs/verdict.md 6a;
docs/studies/2026-11-24-nulls-consistent.md).

* ``windows``: the misfit of the direction-uncertain samples (a stick, where friction is
  a constraint force) leaks through the decimation filter's tail into the first usable
  rows beside a rest; a short window of those rows read 1.6-1.9 x the floor.
* ``state``: the test part is predicted by one fit on the training part; that fit's
  error is structured against position where the test part reaches further than
  training did, and the bin means' null must carry it.
"""
import numpy as np
import pytest

from servo.diagnose.job import diagnose
from servo.diagnose.locate import state_test
from studies.proving.cases import Case, recording
from servo.diagnose.select import integrated_time
from servo.diagnose.verdict import estimation_error, force_floor, window_checks, window_rows


def _null(controller, excitation, rate, seed):
    rec, _ = recording(Case("null", 0.0, controller, excitation, rate), seed)
    return diagnose(rec)


@pytest.fixture(scope="module")
def seeks():
    return _null("open", "seeks", 1000.0, 90018)  # a development null (offset 40000)


@pytest.fixture(scope="module")
def chirp():
    return _null("open", "chirp", 5000.0, 90041)


def test_a_stick_leaks_into_the_rows_beside_a_rest_and_the_windows_skip_them(seeks):
    D = seeks
    sig = D.sig
    r = D.residual_before
    b = D.verdict["baseline_checks"]
    floor, tau = b["level"]["floor"], 1.0
    # the uncertain rows' misfit is hundreds of floors: 1 % of it (the fits' reach) is not noise
    assert np.abs(r[~sig.valid]).max() > 100 * floor
    rows = window_rows(sig)
    assert rows.sum() < sig.valid.sum() and not np.any(rows & ~sig.valid)
    # the first three usable rows beside each run of unusable ones carry the leak
    bad = np.flatnonzero(~sig.valid)
    gap = np.min(np.abs(np.arange(sig.m)[:, None] - bad[None, :]), axis=1)
    first = sig.valid & (gap <= 3)
    assert not np.any(rows & first)
    rms_rows = np.sqrt(np.mean(r[rows] ** 2))
    assert rms_rows < 1.05 * floor  # the windows' rows: at the floor
    assert np.sqrt(np.mean(r[first] ** 2)) > 1.15 * rms_rows  # the rows beside a rest: above it
    old = window_checks(D.design, r, floor, tau, 0.05)  # every usable row, as before
    assert any(w["flagged"] for w in old)
    assert not b["windows"]["failed"] and not b["failed"]
    assert D.verdict["verdict"] == "consistent" and not D.findings


def test_the_training_fits_error_is_the_test_parts_structure_against_position(chirp):
    D = chirp
    sig, design = D.sig, D.design
    r = D.residual_before
    tau = integrated_time(np.where(design.train_valid, r, 0.0))
    plain = state_test(r, sig.valid, tau, D.state, 0.05)
    assert plain["variables"]["position"]["flagged"]  # the diagonal null reads a structure
    # which a fit on every usable row takes out of the test part entirely: the fit's error
    from servo.diagnose.fit import fit_model

    full = fit_model(design, D.baseline, rows=sig.valid)
    r2 = np.where(design.train_rows, r, full.residual)
    assert not state_test(r2, sig.valid, tau, D.state, 0.05)["variables"]["position"]["flagged"]
    est = estimation_error(design, D.baseline_fit)
    assert not state_test(r, sig.valid, tau, D.state, 0.05, est)["variables"]["position"]["flagged"]
    assert D.verdict["verdict"] == "consistent" and not D.findings
    # power kept: a position-dependent force of half the floor on every row is still found
    floor = force_floor(sig, D.final_fit.combined()["inertia"]["J"])
    x = sig.x_rows
    bump = 0.5 * floor * np.where(x < np.quantile(x[sig.valid], 0.2), 1.0, -0.25)
    hit = state_test(r + bump, sig.valid, tau, D.state, 0.05, est)
    assert hit["variables"]["position"]["flagged"]


def test_without_the_fits_error_the_state_test_is_the_diagonal_one():
    rng = np.random.default_rng(3)
    m = 3000
    r = rng.standard_normal(m)
    x = rng.uniform(-1, 1, m)
    valid = np.ones(m, bool)
    variables = {"position": (x, None, "m")}
    a = state_test(r, valid, 1.0, variables, 0.05)["variables"]["position"]
    z = np.array([b["z"] for b in a["bins"]])
    assert a["chi2"] == pytest.approx(float(np.sum(z**2)), rel=1e-12)
    # a zero covariance changes nothing
    b = state_test(r, valid, 1.0, variables, 0.05, (np.ones((m, 2)), np.zeros((2, 2))))["variables"]["position"]
    assert b["chi2"] == pytest.approx(a["chi2"], rel=1e-12)


def test_a_zero_residual_has_no_structure():
    """A model that predicts the rows exactly: every bin mean is zero, p = 1, nothing
    flagged (with the fit's error in the covariance too), not a singular solve."""
    m = 400
    x = np.linspace(-1, 1, m)
    variables = {"position": (x, None, "m"), "direction": (np.sign(np.sin(7 * x)), None, "-")}
    est = (np.column_stack([np.ones(m), x]), np.zeros((2, 2)))
    for e in (None, est):
        out = state_test(np.zeros(m), np.ones(m, bool), 1.0, variables, 0.05, e)["variables"]
        assert all(v["p"] == 1.0 and not v["flagged"] for v in out.values())

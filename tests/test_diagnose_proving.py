"""The proving ground: recordings made with an integrator, friction families,
controllers and excitations that share no code with the project's simulated drive, and
the verdict a diagnosis reaches on them (fixed seeds; the full study with its 200+ null
recordings is ``python -m studies.proving.study``, docs/diagnosis.md section 10)."""
import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from servo.diagnose.job import diagnose
import studies.proving.integrate as ig
from studies.proving.cases import Case, recording

PROVING = Path(__file__).resolve().parents[1] / "studies" / "proving"


def test_the_proving_ground_shares_no_code_with_the_drive():
    """No module of the proving ground imports the kernels, the runtime, the simulated
    experiments or the concealed-effect generator."""
    banned = ("kernels", "servo.runtime", "servo.experiments", "servo.diagnose.concealed", "servo.diagnose.simulate")
    assert len(list(PROVING.glob("*.py"))) >= 5  # the package moved once: a stale path would check nothing
    for py in PROVING.glob("*.py"):
        for node in ast.walk(ast.parse(py.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for n in names:
                assert not n.startswith(banned), f"{py.name} imports {n}"


@pytest.mark.slow
def test_the_command_does_not_load_the_proving_ground():
    code = ("import sys, servo.diagnose.job, servo.diagnose.report, servo.cli.diagnose; "
            "print(any(m.startswith('studies.proving') for m in sys.modules))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"


def _params(**kw):
    p = np.zeros(ig.N_PARAMS)
    p[ig.P_RATE], p[ig.P_J], p[ig.P_NSUB], p[ig.P_COG_PERIOD] = 1000.0, 2.0, 4, 1.0
    for k, v in kw.items():
        p[getattr(ig, "P_" + k)] = v
    return p


def _open_loop(p, w, mk=np.zeros(0), md=np.zeros(0)):
    n = w.size
    u, y, x = np.zeros(n), np.zeros(n), np.zeros(n)
    ig.run(p, np.zeros(n), np.ascontiguousarray(w, float), np.full(n, 1e30), np.ones(n), np.zeros(n),
           np.zeros(1), np.ones(1), mk, md, u, y, x, n)  # fmt: skip
    return x


def test_karnopp_sticks_below_breakaway_and_slides_at_the_coulomb_level():
    p = _params(FC=1.0, FS=1.5, VS=1e-3, DV=1e-9)
    assert np.all(_open_loop(p, np.full(500, 1.4)) == 0.0)  # within breakaway: exactly at rest
    x = _open_loop(p, np.full(500, 3.0))  # beyond: J*x'' = u - Fc once sliding (vs tiny)
    t = np.arange(500) / 1000.0
    a = np.polyfit(t[100:], x[100:], 2)[0] * 2
    assert a == pytest.approx((3.0 - 1.0) / 2.0, rel=1e-3)


def test_a_double_integrator_is_exact_under_a_held_input():
    """RK4 on J*x'' = u with u held per sample: x at the samples is exact (a cubic in t
    per interval is within RK4's order)."""
    rng = np.random.default_rng(0)
    w = rng.standard_normal(200)
    x = _open_loop(_params(), w)
    dt = 1e-3
    v = np.concatenate([[0.0], np.cumsum(w) * dt / 2.0])
    exact = np.concatenate([[0.0], np.cumsum(v[:-1] * dt + w * dt**2 / 4.0)])  # J = 2
    assert np.allclose(x, exact[:-1], rtol=0, atol=1e-14)


def test_maxwell_slip_force_saturates_at_the_sum_of_the_slip_forces():
    """Push the arm through a spring (the Maxwell-slip elements only): a slow ramp far
    beyond every slip distance ends where the force equals the elements' total."""
    md = np.array([1e-3, 2e-3])
    mk = np.array([100.0, 50.0])  # slip forces 0.1 and 0.1
    p = _params(HYST=ig.HYST_MAXWELL, B=50.0)
    x = _open_loop(p, np.full(4000, 0.5), np.ascontiguousarray(mk), np.ascontiguousarray(md))
    v = np.diff(x) * 1000.0
    assert v[-1] == pytest.approx((0.5 - 0.2) / 50.0, rel=1e-3)  # terminal speed: (u - sum f_i)/B


NULLS = [("pdi", "pulses", 20000.0), ("leadlag", "seeks", 50000.0), ("open", "chirp", 1000.0), ("pdi", "prbs", 500.0)]


@pytest.mark.parametrize("controller,excitation,rate", NULLS)
def test_null_recordings_of_the_independent_generator_are_consistent(controller, excitation, rate):
    rec, truth = recording(Case("null", 0.0, controller, excitation, rate), seed=3)
    D = diagnose(rec)
    assert D.findings == [], [f.physics for f in D.findings]
    assert D.verdict["verdict"] == "consistent", D.verdict["text"]
    assert D.final_fit.combined()["inertia"]["J"] == pytest.approx(truth["J"], rel=0.02)


@pytest.mark.parametrize("family,size,controller,excitation,rate", [
    ("lugre", 0.5, "leadlag", "seeks", 50000.0),
    ("delay", 1.0, "leadlag", "seeks", 50000.0),
    ("mode_in_band", 3e-2, "leadlag", "seeks", 20000.0),
])  # fmt: skip
def test_an_effect_of_another_family_is_named_by_its_nearest_term_and_explained(family, size, controller, excitation,
                                                                                rate):  # fmt: skip
    rec, truth = recording(Case(family, size, controller, excitation, rate), seed=5)
    D = diagnose(rec)
    assert [f.physics for f in D.findings][:1] == [truth["expect"]]
    assert D.verdict["verdict"] == "explained", D.verdict["text"]
    assert D.verdict["baseline_checks"]["failed"]  # the baseline did fail


def test_a_saturation_that_bites_only_late_is_unexplained_and_located():
    """The amplifier clips only in the last 30 %: the training part never sees it, so no
    term can be fitted; the verdict names the gap and what the test part reaches."""
    rec, truth = recording(Case("saturation_late", 0.1, "pdi", "multisine", 5000.0), seed=2)
    D = diagnose(rec)
    v = D.verdict
    assert v["verdict"] == "unexplained", v["text"]
    assert v["final_checks"]["gap"]["failed"]
    assert "train/test gap" in v["text"] and "no term of the vocabulary" in v["text"]
    wins = v["final_checks"]["windows"]["windows"]
    worst = max(wins, key=lambda w: w["ratio"])
    assert worst["t1"] >= 0.7 * rec.t[-1]  # the worst window is where the clipping is
    assert any(r["variable"] == "u" for r in v["final_checks"]["gap"]["beyond_training"])


def test_an_unrelated_position_is_out_of_scope():
    rec, truth = recording(Case("out_of_scope", 0.0, "pdi", "multisine", 5000.0), seed=1)
    D = diagnose(rec)
    assert D.verdict["verdict"] == "out_of_scope", D.verdict["text"]
    assert "inertia" in D.verdict["text"]
    assert D.findings == []  # nothing is named on a recording the force balance does not describe


@pytest.mark.slow
def test_the_study_command_scores_what_it_ran(tmp_path):
    """``python -m studies.proving.study`` in this process: the runs in the jobs'
    order, the seeds offset as asked, the tables written; an unknown family is refused."""
    import json

    from studies.proving import study

    out = tmp_path / "st"
    assert study.main(["--nulls", "2", "--seeds", "1", "--families", "out_of_scope", "--workers", "0",
                       "--seed-offset", "7", "--out", str(out)]) == 0  # fmt: skip
    runs = json.loads((out / "study.json").read_text())
    assert [(r["family"], r["seed"]) for r in runs] == [("null", 50_007), ("null", 50_008), ("out_of_scope", 60_007)]
    assert runs[2]["verdict"] == "out_of_scope"
    assert "| null recordings |" in (out / "study.md").read_text()
    with pytest.raises(SystemExit):
        study.main(["--families", "no_such_family", "--out", str(tmp_path / "x")])


def test_every_familys_twin_is_the_null_recording_of_its_seed():
    """The study measures an effect against its twin (size 0, :mod:`proving.twin`): for
    every family the twin must be exactly the recording without the effect, the null of
    the same seed and combination (the same noise, excitation and plant), bit for bit."""
    from dataclasses import replace

    from studies.proving.cases import FAMILIES

    for family in FAMILIES:
        if family in ("null", "out_of_scope"):
            continue
        case = Case(family, 0.0, "leadlag", "prbs", 5000.0)
        twin, _ = recording(case, 7)
        null, _ = recording(replace(case, family="null"), 7)
        assert np.array_equal(twin.x, null.x) and np.array_equal(twin.u, null.u), family

"""``servo fleet`` in this process: distributions, robust outliers, the table, resume,
failing recordings, the Monte Carlo closed loop, the verdict column, bad input."""
import json
import re

import numpy as np
import pyarrow.parquet as pq
import pytest

from servo.cli import main
from servo.config import Config
from servo.diagnose.concealed import concealed_recording
from servo.diagnose.job import Options, diagnose
from servo.diagnose.report import build_report
from servo.errors import ConfigError, Interrupted
from servo.fleet import identify as fleet_identify
from kernels.compose import LOG_COLUMNS
from servo.fleet.closedloop import run_scenario
from servo.run.reduce import COL
from studies.proving.cases import Case, recording
from servo.fleet import diagnose as fleet_diagnose
from servo.fleet.diagnose import flag, row_of_report
from servo.fleet.job import run_fleet
from servo.fleet.outliers import outliers, robust_z
from servo.fleet.runner import Where, batches
from servo.fleet.sources import recording_tasks, sources
from servo.fleet.spec import draw_drive, draw_drives, parse_spec
from servo.fleet.synthetic import synthetic_drives, write_fleet
from servo.run.job import run_simulated

LAG = 1e-5  # half a sample at 50 kHz: the zero-order hold of the recorded command


# ---------------------------------------------------------------- distributions


def test_specs_resolve_percentages_and_bounds():
    d = parse_spec("drive.Fc", "normal(1e-3, 10%)")
    assert (d.kind, d.a) == ("normal", 1e-3) and d.b == pytest.approx(1e-4)
    u = parse_spec("drive.K", "uniform(0.1, 20%)")
    assert (u.a, u.b) == pytest.approx((0.08, 0.12))
    ln = parse_spec("drive.Ha", "lognormal(1e-3, 15%)")
    assert (ln.a, ln.b) == pytest.approx((1e-3, 0.15))


@pytest.mark.parametrize("key,text,words", [
    ("drive.Fx", "normal(1, 1)", "unknown field"),
    ("run.seed", "normal(1, 1)", "only [drive]"),
    ("drive.mode_hz", "normal(1, 1)", "only number fields"),
    ("drive.substeps", "normal(2, 1)", "only number fields"),
    ("drive.Fc", "gauss(1e-3, 1e-4)", "expected normal(A, B)"),
    ("drive.Fc", "normal(1e-3)", "expected normal(A, B)"),
    ("drive.Fc", "normal(abc, 1)", "not a number"),
    ("drive.Fc", "normal(1e-3, -1e-4)", "standard deviation"),
    ("drive.Fc", "normal(-1e-3, 1e-4)", "outside the field's range"),
    ("drive.sigma", "uniform(0, 100)", "outside the field's range"),
    ("drive.J", "uniform(2e-3, 1e-3)", "upper bound"),
    ("drive.Ha", "lognormal(0, 10%)", "median must be > 0"),
])  # fmt: skip
def test_bad_specs_are_one_line_naming_the_field(key, text, words):
    with pytest.raises(ConfigError) as e:
        parse_spec(key, text)
    msg = str(e.value)
    assert words in msg and key in msg and "\n" not in msg


def test_draws_follow_their_distribution_and_stay_in_the_fields_range():
    dists = [parse_spec("drive.B", "normal(1e-4, 150%)"), parse_spec("drive.Ha", "lognormal(1e-3, 20%)"),
             parse_spec("drive.J", "uniform(0.9e-3, 1.1e-3)")]  # fmt: skip
    drives = draw_drives(dists, 2000, seed=5)
    B = np.array([d["B"] for d in drives])
    Ha = np.array([d["Ha"] for d in drives])
    J = np.array([d["J"] for d in drives])
    assert B.min() >= 0.0 and (B == 0).sum() == 0  # truncated to B >= 0: redrawn, not clipped
    assert np.median(Ha) == pytest.approx(1e-3, rel=0.03)
    assert np.std(np.log(Ha)) == pytest.approx(0.2, rel=0.08)
    assert 0.9e-3 <= J.min() and J.max() <= 1.1e-3 and np.mean(J) == pytest.approx(1e-3, rel=0.01)
    # drive i does not depend on the fleet's size (resume of a larger fleet)
    assert draw_drives(dists, 3, seed=5) == drives[:3] and draw_drive(dists, 5, 1999) == drives[1999]


# ---------------------------------------------------------------- outliers


def test_robust_outliers_find_the_planted_drives_and_ignore_constant_columns():
    rng = np.random.default_rng(0)
    x = rng.normal(10.0, 1.0, 200)
    x[[17, 123]] = [25.0, -8.0]  # 15 and 18 standard deviations out
    rows = [{"drive": f"d{i}", "status": "ok", "p": float(v), "const": 1.0} for i, v in enumerate(x)]
    rows.append({"drive": "bad", "status": "error", "p": 1e9})  # a failed drive is not scored
    found = outliers(rows, ["p", "const"])
    assert [(o.drive, o.column) for o in found] == [("d123", "p"), ("d17", "p")]
    assert found[0].z < -3.5 < 3.5 < found[1].z
    z, med, mad = robust_z(x)
    assert med == pytest.approx(10.0, abs=0.2) and 1.4826 * mad == pytest.approx(1.0, rel=0.15)


def test_batches_cover_the_tasks_in_order_and_feed_every_worker():
    tasks = list(range(103))
    for size, workers in ((1, 2), (16, 2), (16, 8), (500, 1)):
        groups = batches(tasks, size, workers)
        assert [t for g in groups for t in g] == tasks
        assert max(len(g) for g in groups) <= size
        assert len(groups) >= min(len(tasks), 4 * workers)


# ---------------------------------------------------------------- recordings fleets


@pytest.fixture(scope="module")
def small_fleet(tmp_path_factory):
    """Six defect-free synthetic drives (0.4 s each) and one malformed recording."""
    d = tmp_path_factory.mktemp("fleet")
    drives = synthetic_drives(6, 0, seed=3)
    write_fleet(d, drives, duration_s=0.4)
    (d / "broken.csv").write_text("t,u,x\n0,0,0\n1e-5,nan,0\n" + "".join(f"{k * 1e-5},0,0\n" for k in range(2, 40)))
    return d, {sd.name: sd.drive for sd in drives}


def test_identify_fleet_estimates_each_drive_and_a_failing_recording_keeps_its_error(small_fleet, tmp_path):
    d, truth = small_fleet
    s = fleet_identify.settings(force_lag_s=LAG)
    tasks = recording_tasks(sources([str(d / "drive*.npz"), str(d / "broken.csv")]), s)
    summary = run_fleet("identify", tasks, s, tmp_path / "out", Where(workers=0))
    rows = pq.read_table(tmp_path / "out" / "fleet.parquet").to_pylist()
    assert [r["drive"] for r in rows] == sorted(truth) + ["broken"]
    assert (summary["ok"], summary["failed"]) == (6, 1)
    bad = rows[-1]
    assert bad["status"] == "error" and "NaN" in bad["error"] and "\n" not in bad["error"] and bad["J"] is None
    for r in rows[:-1]:  # each drive's own parameters, not the population's
        t = truth[r["drive"]]
        assert r["status"] == "ok" and r["error"] is None
        # errors well inside the spreads (J 3 %, Fc 10 %, h0 and K 20 %, synthetic.SPREAD)
        assert r["J"] == pytest.approx(t["J"], rel=0.003)
        assert r["Fc"] == pytest.approx(t["Fc"], rel=0.02)
        assert r["h0"] == pytest.approx(t["h0"], rel=0.02)
        assert r["K"] == pytest.approx(t["K"], rel=0.15)
        assert r["J_std"] > 0 and r["rel_error_pct"] < 5
        assert json.loads(r["settings"]) == s and len(r["sha256"]) == 64
    report = (tmp_path / "out" / "fleet_report.md").read_text()
    assert "## Failed drives (1)" in report and "broken" in report and "## Robust outliers" in report
    assert {"histograms.png", "scatter.png", "fleet.parquet", "fleet_report.md", "fleet.json"} <= {
        p.name for p in (tmp_path / "out").iterdir()}  # fmt: skip


def test_resume_skips_drives_already_done_by_content_and_settings(small_fleet, tmp_path):
    d, truth = small_fleet
    fleet = tmp_path / "recs"
    fleet.mkdir()
    for name in truth:
        (fleet / f"{name}.npz").write_bytes((d / f"{name}.npz").read_bytes())
    s = fleet_identify.settings(force_lag_s=LAG)
    runs = iter(range(100))

    def go(settings, resume=None):
        out = tmp_path / f"out{next(runs)}"
        tasks = recording_tasks(sources([str(fleet / "*.npz")]), settings)
        return run_fleet("identify", tasks, settings, out, Where(workers=0), resume=resume, plots=False), out

    first, out0 = go(s)
    table1 = pq.read_table(out0 / "fleet.parquet")
    assert first["resumed"] == 0
    again, out1 = go(s, out0)
    assert again["resumed"] == 6 and pq.read_table(out1 / "fleet.parquet").equals(table1)
    # one recording changed: only it runs again
    names = sorted(truth)
    (fleet / f"{names[2]}.npz").write_bytes((d / f"{names[0]}.npz").read_bytes())
    third, out2 = go(s, out1)
    assert third["resumed"] == 5
    rows = pq.read_table(out2 / "fleet.parquet").to_pylist()
    assert rows[2]["J"] == rows[0]["J"] and rows[2]["sha256"] == rows[0]["sha256"]
    # other settings: nothing is reused
    assert go(fleet_identify.settings(force_lag_s=0.0), out2)[0]["resumed"] == 0


def test_a_fleet_stopped_half_way_continues_with_resume(small_fleet, tmp_path, monkeypatch):
    import servo.fleet.job as job_mod

    d, truth = small_fleet
    monkeypatch.setattr(job_mod, "CHECKPOINT_S", 0.0)  # a checkpoint after every drive
    s = fleet_identify.settings(force_lag_s=LAG)
    tasks = recording_tasks(sources([str(d / "drive*.npz")]), s)
    seen = []

    def stop_after_three(rows):
        seen.extend(rows)
        if len(seen) == 3:
            raise KeyboardInterrupt  # Ctrl-C half-way

    out = tmp_path / "out"
    with pytest.raises(Interrupted) as e:
        run_fleet("identify", tasks, s, out, Where(workers=0), progress=stop_after_three)
    assert f"continue with --resume {out} --out {out}" in str(e.value)
    assert not out.exists()  # nothing partial in the final folder: the drives done wait in OUT.incomplete
    partial = pq.read_table(tmp_path / "out.incomplete" / "fleet.parquet").to_pylist()
    assert [r["drive"] for r in partial] == sorted(truth)[:3]
    summary = run_fleet("identify", tasks, s, out, Where(workers=0), resume=out, plots=False)
    assert (summary["resumed"], summary["ok"]) == (3, 6)
    assert sorted(p.name for p in out.iterdir()) == ["fleet.json", "fleet.parquet", "fleet_report.md", "report.html"]
    assert not (tmp_path / "out.incomplete").exists()
    fresh = run_fleet("identify", tasks, s, tmp_path / "fresh", Where(workers=0), plots=False)
    assert fresh["resumed"] == 0
    assert pq.read_table(out / "fleet.parquet").equals(pq.read_table(tmp_path / "fresh" / "fleet.parquet"))


# ---------------------------------------------------------------- diagnosis rows


def test_the_diagnosis_row_picks_up_findings_and_a_verdict_when_the_report_has_one():
    rec, _ = concealed_recording("hysteresis", 1e-3, seed=2)
    report = build_report(diagnose(rec, Options()))
    row = row_of_report(report)
    assert row["findings"] == "hysteresis" and row["flagged"] and row["n_findings"] == 1
    assert row["hysteresis.Ha"] == pytest.approx(1e-3, rel=0.3) and row["hysteresis.Ha_std"] > 0
    assert row["test_force_rel_pct_after"] < row["test_force_rel_pct_before"]
    assert row["verdict"] == report["verdict"] == "explained"  # the diagnosis's own verdict, carried over
    assert row["flag_reason"] == "findings: hysteresis" and row["verdict_text"] == report["verdict_text"]
    assert "verdict" not in row_of_report({k: v for k, v in report.items() if k != "verdict"})
    assert row_of_report({**report, "verdict": "defect"})["verdict"] == "defect"
    v = row_of_report({**report, "verdict": {"flag": True, "why": "hysteresis"}})["verdict"]
    assert json.loads(v) == {"flag": True, "why": "hysteresis"}


def test_flag_accounts_for_the_verdict_as_well_as_the_findings():
    assert flag([], "consistent", "fine") == (False, None)
    assert flag(["hysteresis"], "explained", "ok") == (True, "findings: hysteresis")
    assert flag([], "unexplained", "the model still fails: x") == (True, "verdict unexplained: the model still fails: x")
    assert flag(["offset"], "out_of_scope", None) == (True, "findings: offset; verdict out_of_scope")
    assert flag([], {"verdict": "unexplained"}) == (False, None)  # a table is not one of the verdicts


@pytest.mark.slow
def test_drives_the_model_does_not_describe_are_flagged_with_the_reason_though_nothing_is_found(tmp_path):
    """The position of an unrelated run (out of scope), whatever it finds, and a clipping the
    training part never sees stays unexplained whatever is found; the fleet flags both and
    says why, the verdict's text included.  A null drive is not flagged."""
    recs = {"late_clip": recording(Case("saturation_late", 0.1, "pdi", "multisine", 5000.0), seed=2)[0],
            "unrelated": recording(Case("out_of_scope", 0.0, "pdi", "multisine", 5000.0), seed=1)[0],
            "null": concealed_recording(None, 0.0, seed=1)[0]}  # fmt: skip
    for name, rec in recs.items():
        np.savez(tmp_path / f"{name}.npz", t=rec.t, u=rec.u, x=rec.x)
    s = fleet_diagnose.settings()
    tasks = recording_tasks(sources([str(tmp_path / f"{n}.npz") for n in recs]), s)
    summary = run_fleet("diagnose", tasks, s, tmp_path / "out", Where(workers=0), plots=False)
    rows = {r["drive"]: r for r in pq.read_table(tmp_path / "out" / "fleet.parquet").to_pylist()}
    late, unrelated, null = rows["late_clip"], rows["unrelated"], rows["null"]
    assert late["verdict"] == "unexplained" and late["flagged"], late
    assert "verdict unexplained: the model still fails" in late["flag_reason"]
    assert "no term of the vocabulary" in late["flag_reason"]
    assert unrelated["verdict"] == "out_of_scope" and unrelated["flagged"], unrelated  # findings or not
    assert "verdict out_of_scope: " in unrelated["flag_reason"] and "inertia" in unrelated["flag_reason"]
    assert null["verdict"] == "consistent" and not null["flagged"] and null["flag_reason"] is None
    assert not null["findings"]
    assert summary["flagged"] == ["late_clip", "unrelated"]
    report = (tmp_path / "out" / "fleet_report.md").read_text()
    assert "## Flagged drives (2 of 3)" in report
    assert re.search(r"^\| late_clip \| .* \| unexplained \| .*verdict unexplained: the model still fails", report, re.M)
    assert re.search(r"^\| unrelated \| .* \| out_of_scope \| .*verdict out_of_scope: ", report, re.M), report
    assert "| null |" not in report


# ---------------------------------------------------------------- Monte Carlo


def test_the_in_memory_scenario_is_servo_runs_fast_path_bit_for_bit(tmp_path):
    cfg = Config().replace(run={"duration_s": 0.1})
    mem = run_scenario(cfg, True)
    run_simulated(cfg, tmp_path, True, fast=True)
    with np.load(tmp_path / "log_compensated.npz") as z:
        logged = np.column_stack([z[c] for c in LOG_COLUMNS])
    assert mem.shape == logged.shape and np.array_equal(mem, logged)
    assert not list(tmp_path.glob("*.journal"))


def test_simulate_fleet_compensation_removes_the_hysteresis_tail_of_every_drawn_drive(tmp_path, capsys):
    out = tmp_path / "mc"
    (tmp_path / "spread.toml").write_text('[drive]\nsigma = "normal(320, 10%)"\n')
    argv = ["fleet", "simulate", "--drives", "5", "--duration", "0.12", "--workers", "0", "--seed", "7",
            "--vary", "drive.Ha=lognormal(1e-3, 20%)", "--spread", str(tmp_path / "spread.toml"), "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    assert "5 drives, 5 ok" in capsys.readouterr().out
    rows = pq.read_table(out / "fleet.parquet").to_pylist()
    assert len({r["drive.Ha"] for r in rows}) == 5
    for r in rows:
        # the 0.3 um step never leaves pre-sliding: uncompensated it drags the Dahl
        # element's tail (~30 ms); compensated it settles far sooner
        assert r["comp_step1_settling_ms"] < 0.6 * r["uncomp_step1_settling_ms"]
        assert r["uncomp_step1_settling_ms"] > 25.0
        assert r["comp_rms_step1_m"] < r["uncomp_rms_step1_m"]
    # the compensator keeps the nominal sigma (320 A/m): in pre-sliding the drive whose
    # own sigma is furthest from it is the worst compensated
    worst = max(rows, key=lambda r: abs(r["drive.sigma"] - 320.0))
    assert worst["comp_step1_overshoot_pct"] == max(r["comp_step1_overshoot_pct"] for r in rows)
    assert worst["comp_step1_settling_ms"] == max(r["comp_step1_settling_ms"] for r in rows)
    # a row is the closed loop of its drawn drive (not another drive's)
    cfg = Config().replace(run={"duration_s": 0.12}, drive={"Ha": rows[3]["drive.Ha"], "sigma": rows[3]["drive.sigma"]})
    log = run_scenario(cfg, True)
    e = log[:, COL["e"]]
    assert rows[3]["comp_error_rms_m"] == float(np.sqrt(np.mean(np.square(e))))



def test_a_fleet_too_small_to_pay_a_cluster_runs_in_this_process(tmp_path, capsys):
    """Without ``--workers`` or ``--scheduler``, a fleet smaller than its command's
    ``CLUSTER_MIN`` (a cluster's start, 4-8 s idle, against the drives' own time) runs in
    this process; ``--workers N`` or a scheduler keeps the cluster asked for."""
    from servo.fleet import diagnose as d, identify as i, simulate as s
    from servo.fleet.runner import placed

    assert s.CLUSTER_MIN > 200 and i.CLUSTER_MIN > 200 and 4 < d.CLUSTER_MIN <= 40
    assert placed(Where(batch=3), 255, 256) == Where(workers=0, batch=3)
    assert placed(Where(), 256, 256) == Where()
    assert placed(Where(workers=2), 10, 256) == Where(workers=2)
    assert placed(Where(scheduler="tcp://h:1"), 10, 256) == Where(scheduler="tcp://h:1")
    out = tmp_path / "mc"
    argv = ["fleet", "simulate", "--drives", "6", "--duration", "0.05", "--vary", "drive.Ha=lognormal(1e-3, 20%)",
            "--no-plots", "--quiet", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "6 drives, 6 ok" in printed and "ran on this process" in printed, printed


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize("argv,words", [
    (["fleet", "identify"], "no recordings"),
    (["fleet", "identify", "/nonexistent/*.npz"], "no file matches"),
    (["fleet", "diagnose", "/nonexistent.csv"], "no such file"),
    (["fleet", "diagnose", "--baseline", "J,X", "x.csv"], "X"),
    (["fleet", "simulate", "--vary", "drive.Fc=gauss(1, 2)"], "expected normal(A, B)"),
    (["fleet", "simulate", "--vary", "drive.Fc=normal(1e-3, 10%)"], "drive.Fs"),
    (["fleet", "simulate"], "nothing varies"),
    (["fleet", "simulate", "--spread", "missing.toml"], "no such file"),
    (["fleet", "simulate", "--spread", "x.csv"], "x.csv"),
    (["fleet", "simulate", "--vary", "drive.Ha=normal(1e-3, 10%)", "--workers", "-1"], "--workers"),
    (["fleet", "simulate", "--vary", "drive.Ha=normal(1e-3, 10%)", "--workers", "2", "--scheduler", "tcp://x:1"],
     "--scheduler"),
])  # fmt: skip
def test_bad_fleet_input_is_one_line_and_exit_2(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if "x.csv" in argv:
        (tmp_path / "x.csv").write_text("t,u,x\n")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("servo: error: ") and err.count("\n") == 1 and words in err, err
    assert not (tmp_path / "servo-out").exists()


def test_a_manifest_maps_columns_and_names_drives(tmp_path):
    rec, _ = concealed_recording(None, 0.0, seed=1)
    data = np.column_stack([rec.t, rec.u * 2.0, rec.x])
    np.savetxt(tmp_path / "r.csv", data, delimiter=",", header="time,cmd,pos", comments="")
    (tmp_path / "m.csv").write_text("drive,path,columns,scale\nunit7,r.csv,\"t=time,u=cmd,x=pos\",u=0.5\n")
    (tmp_path / "bad.csv").write_text("drive,file\nx,y\n")
    src = sources([], str(tmp_path / "m.csv"))
    assert src[0].drive == "unit7" and src[0].columns == "t=time,u=cmd,x=pos"
    row = fleet_identify.run(src[0], fleet_identify.settings(force_lag_s=LAG))
    assert row["J"] == pytest.approx(1e-3, rel=0.005)  # the scale undid the factor 2
    with pytest.raises(ConfigError, match="path"):
        sources([], str(tmp_path / "bad.csv"))

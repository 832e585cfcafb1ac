"""``servo fleet``'s results and outputs: keyed by everything that shapes a row, one row
per recording path, staged like every command's (``OUT.incomplete/`` renamed when
complete; ``--out`` new or empty), one writer per output, nothing partial in the final
folder on Ctrl-C or a full disk; a ``--scheduler`` that is not Dask, and fleet sizes
beyond the budget, refused in one line; ``fleet diagnose --decimate`` as
``servo diagnose``'s."""
import errno
import http.server
import os
import socket
import threading
import time

import pyarrow.parquet as pq
import pytest

import servo.fleet.job as job_mod
from servo.cli import build_parser, main
from servo.errors import ConfigError
from servo.fleet import diagnose as fleet_diagnose
from servo.fleet import identify as fleet_identify
from servo.fleet.job import run_fleet
from servo.fleet.runner import Where
from servo.fleet.sources import recording_tasks, sources
from servo.fleet.synthetic import synthetic_drives, write_fleet
from servo.fleet.task import MAX_DRIVES
from servo.io.outdir import lock

LAG = 1e-5  # half a sample at 50 kHz: the zero-order hold of the recorded command


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    """Four defect-free synthetic drives (0.3 s each) and their true fields."""
    d = tmp_path_factory.mktemp("recs")
    drives = synthetic_drives(4, 0, seed=5)
    write_fleet(d / "fleet", drives, duration_s=0.3)
    return d / "fleet", {sd.name: sd.drive for sd in drives}


def _identify(argv, capsys):
    code = main(["fleet", "identify", "--force-lag", str(LAG), "--workers", "0", "--no-plots", *argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _rows(out):
    return pq.read_table(out / "fleet.parquet").to_pylist()


# ---------------------------------------------------------------- the resume key


def test_the_resume_key_holds_the_mapping_the_scales_and_the_code_versions(recs):
    d, _ = recs
    s = fleet_identify.settings(force_lag_s=LAG)
    key = {}
    for label, scale, columns in (("plain", None, None), ("scaled", "u=1000", None), ("mapped", None, "t=t,u=u,x=x")):
        key[label] = recording_tasks(sources([str(d / "drive0000.npz")], columns=columns, scale=scale), s)[0].key
    assert len(set(key.values())) == 3
    assert recording_tasks(sources([str(d / "drive0000.npz")]), s)[0].key == key["plain"]  # and it is stable
    from servo.fleet.task import code_versions, task_key

    v = code_versions()
    assert v["servo"] and v["numpy"] and v["numba"]
    assert task_key("h", s, versions=v) != task_key("h", s, versions={**v, "servo": v["servo"] + ".post1"})


def test_resume_with_another_scale_runs_every_drive_again(recs, tmp_path, capsys):
    """Four drives identified, then again with --scale u=1000 --resume: J is 1000 times
    the first (a fresh run's), none resumed; the same scale again resumes all four."""
    d, truth = recs
    glob = str(d / "drive*.npz")
    code, out, _ = _identify([glob, "--out", str(tmp_path / "a")], capsys)
    assert code == 0 and "4 ok" in out
    code, out, _ = _identify([glob, "--scale", "u=1000", "--resume", str(tmp_path / "a"), "--out", str(tmp_path / "b")],
                             capsys)  # fmt: skip
    assert code == 0 and "resumed" not in out, out
    a, b = _rows(tmp_path / "a"), _rows(tmp_path / "b")
    for ra, rb in zip(a, b):
        assert rb["J"] == pytest.approx(1000 * ra["J"], rel=1e-9)
        assert ra["J"] == pytest.approx(truth[ra["drive"]]["J"], rel=0.01)
    code, out, _ = _identify([glob, "--scale", "u=1000", "--resume", str(tmp_path / "b"), "--out", str(tmp_path / "c")],
                             capsys)  # fmt: skip
    assert code == 0 and "4 resumed" in out
    assert pq.read_table(tmp_path / "c" / "fleet.parquet").equals(pq.read_table(tmp_path / "b" / "fleet.parquet"))


def test_recordings_with_identical_bytes_are_each_their_own_drive(recs, tmp_path):
    d, _ = recs
    src = (d / "drive0001.npz").read_bytes()
    for name in ("alpha", "bravo", "charlie"):
        (tmp_path / f"{name}.npz").write_bytes(src)
    s = fleet_identify.settings(force_lag_s=LAG)
    tasks = recording_tasks(sources([str(tmp_path / "*.npz")]), s)
    run_fleet("identify", tasks, s, tmp_path / "out", Where(workers=0), plots=False)
    rows = _rows(tmp_path / "out")
    assert [r["drive"] for r in rows] == ["alpha", "bravo", "charlie"]
    assert [os.path.basename(r["source"]) for r in rows] == ["alpha.npz", "bravo.npz", "charlie.npz"]
    assert len({r["sha256"] for r in rows}) == 1
    summary = run_fleet("identify", tasks, s, tmp_path / "again", Where(workers=0), resume=tmp_path / "out", plots=False)
    assert summary["resumed"] == 3
    assert [r["drive"] for r in _rows(tmp_path / "again")] == ["alpha", "bravo", "charlie"]
    assert [r["source"] for r in _rows(tmp_path / "again")] == [r["source"] for r in rows]


# ---------------------------------------------------------------- staged outputs


def test_no_fleet_command_writes_into_a_folder_that_holds_files(recs, tmp_path, capsys):
    d, _ = recs
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "manifest.csv").write_text("my own manifest\n")
    (mine / "fleet_report.md").write_text("my own report\n")
    for argv in (["fleet", "synthetic", "--drives", "2", "--duration", "0.05", "--out", str(mine)],
                 ["fleet", "identify", str(d / "drive0000.npz"), "--workers", "0", "--out", str(mine)]):  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("servo: error: ") and err.count("\n") == 1 and "not an empty folder" in err, err
    assert sorted(p.name for p in mine.iterdir()) == ["fleet_report.md", "manifest.csv"]
    assert (mine / "manifest.csv").read_text() == "my own manifest\n"
    assert (mine / "fleet_report.md").read_text() == "my own report\n"
    assert not list(tmp_path.glob("*.incomplete"))


def test_a_second_fleet_on_the_same_out_is_refused_while_the_first_runs(recs, tmp_path, capsys, monkeypatch):
    """The second command starts while the first is half-way (from the first's progress
    callback): refused in one line, also when it asks to continue the first's staging
    folder; the first finishes with every drive."""
    d, _ = recs
    monkeypatch.setattr(job_mod, "CHECKPOINT_S", 0.0)  # the first's staging folder holds a table
    out = tmp_path / "out"
    s = fleet_identify.settings(force_lag_s=LAG)
    tasks = recording_tasks(sources([str(d / "drive*.npz")]), s)
    codes = []

    def second_writer(rows):
        if not codes:
            codes.append(main(["fleet", "identify", str(d / "drive0000.npz"), "--workers", "0", "--out", str(out)]))
            codes.append(main(["fleet", "identify", str(d / "drive0000.npz"), "--workers", "0", "--out", str(out),
                               "--resume", str(out)]))  # fmt: skip

    summary = run_fleet("identify", tasks, s, out, Where(workers=0), plots=False, progress=second_writer)
    err = capsys.readouterr().err.splitlines()
    assert codes == [2, 2], err
    assert all(e.startswith("servo: error: ") for e in err) and len(err) == 2, err
    assert "another command is writing it" in err[1], err
    assert summary["ok"] == 4 and len(_rows(out)) == 4
    assert not (tmp_path / "out.incomplete").exists()


def test_a_staging_folder_locked_by_a_live_writer_is_not_taken_over(tmp_path):
    from servo.errors import ServoError

    staging = tmp_path / "out.incomplete"
    staging.mkdir()
    (staging / "fleet.parquet").write_bytes(b"")
    import subprocess
    import sys

    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDONLY); "
                               "fcntl.flock(fd, fcntl.LOCK_EX); print('held', flush=True); time.sleep(60)", str(staging)],
                              stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(ServoError, match="another command is writing it"):
            lock(staging)
    finally:
        holder.kill()
        holder.wait()
    os.close(lock(staging))  # its writer gone, the folder can be continued


def test_ctrl_c_or_a_full_disk_leave_nothing_in_the_final_folder(recs, tmp_path, capsys, monkeypatch):
    d, _ = recs
    monkeypatch.setattr(job_mod, "CHECKPOINT_S", 0.0)  # a checkpoint table after every drive
    glob = str(d / "drive*.npz")

    import servo.fleet.runner as runner_mod

    real = runner_mod.Progress.__call__
    calls = []

    def interrupt_on_the_third(self, rows):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(self, rows)

    monkeypatch.setattr(runner_mod.Progress, "__call__", interrupt_on_the_third)
    out = tmp_path / "ctrlc"
    code, _, err = _identify([glob, "--out", str(out)], capsys)
    assert code == 130 and err.count("\n") == 1 and err.startswith("servo: interrupted; the drives done so far kept in")
    assert f"--resume {out}" in err
    assert not out.exists() and len(_rows(tmp_path / "ctrlc.incomplete")) == 3
    monkeypatch.setattr(runner_mod.Progress, "__call__", real)
    code, text, err = _identify([glob, "--resume", str(out), "--out", str(out)], capsys)
    assert code == 0 and "3 resumed" in text, err
    assert len(_rows(out)) == 4 and not (tmp_path / "ctrlc.incomplete").exists()

    # a full disk when the final table is written: the final folder is not made
    import servo.fleet.table as table_mod

    real_write = table_mod.pq.write_table
    writes = []

    def disk_full_at_the_end(table, where, *a, **k):
        writes.append(table.num_rows)
        if table.num_rows == 4:  # as pyarrow says it, naming no file
            raise OSError(errno.ENOSPC, "Error writing bytes to file. Detail: [errno 28] No space left on device")
        return real_write(table, where, *a, **k)

    monkeypatch.setattr(table_mod.pq, "write_table", disk_full_at_the_end)
    full = tmp_path / "full"
    code, _, err = _identify([glob, "--out", str(full)], capsys)
    assert code == 2 and err.count("\n") == 1 and f"{full}.incomplete/fleet.parquet: No space left on device" in err, err
    assert not full.exists()
    assert "the drives done so far kept in" in err and not list((tmp_path / "full.incomplete").glob(".*tmp"))


# ---------------------------------------------------------------- endpoints and sizes


class _Banner(threading.Thread):
    """A listener on 127.0.0.1 that greets every connection with a line of text."""

    def __init__(self):
        super().__init__(daemon=True)
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]

    def run(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            conn.sendall(b"SSH-2.0-OpenSSH_9.2p1 Debian-2\r\n")
            time.sleep(0.2)
            conn.close()


@pytest.mark.parametrize("kind", ["banner", "http"])
def test_a_scheduler_address_that_is_not_dask_is_one_line_within_the_connect_timeout(kind, tmp_path, capsys,
                                                                                    monkeypatch):  # fmt: skip
    import servo.fleet.runner as runner_mod

    monkeypatch.setattr(runner_mod, "CONNECT_TIMEOUT_S", 1.0)
    if kind == "banner":
        server = _Banner()
        server.start()
        port, stop = server.port, server.sock.close
    else:
        httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
        threading.Thread(target=httpd.serve_forever, daemon=True).start()
        port, stop = httpd.server_address[1], httpd.shutdown
    try:
        code = main(["fleet", "simulate", "--drives", "5", "--vary", "drive.Ha=lognormal(1e-3, 20%)",
                     "--scheduler", f"tcp://127.0.0.1:{port}", "--out", str(tmp_path / "out")])  # fmt: skip
        t0 = time.monotonic()
        with pytest.raises(ConfigError, match="not a Dask scheduler"):
            runner_mod.probe_scheduler(f"tcp://127.0.0.1:{port}")
        took = time.monotonic() - t0
    finally:
        stop()
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("servo: error: fleet: --scheduler") and err.count("\n") == 1, err
    assert "not a Dask scheduler" in err and took < 1.0 + 1.0
    if kind == "banner":
        assert "SSH-2.0-" in err
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.incomplete").exists()


@pytest.mark.parametrize("argv", [
    ["fleet", "simulate", "--drives", "1000000000", "--vary", "drive.Ha=lognormal(1e-3, 20%)"],
    ["fleet", "synthetic", "--drives", "1000000000", "--out", "syn"],
])  # fmt: skip
def test_fleet_sizes_beyond_the_budget_are_one_line_before_anything_is_drawn(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    t0 = time.monotonic()
    assert main(argv) == 2
    assert time.monotonic() - t0 < 5.0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "1000000000 drives" in err and f"at most {MAX_DRIVES}" in err, err
    assert not list(tmp_path.iterdir())


def test_a_manifest_beyond_the_budget_is_one_line(tmp_path, capsys):
    (tmp_path / "r.csv").write_text("t,u,x\n0,0,0\n")
    (tmp_path / "m.csv").write_text("drive,path\n" + "".join(f"d{i},r.csv\n" for i in range(MAX_DRIVES + 5)))
    assert main(["fleet", "identify", "--manifest", str(tmp_path / "m.csv"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"over {MAX_DRIVES} drives" in err and f"at most {MAX_DRIVES}" in err, err


# ---------------------------------------------------------------- one vocabulary


def test_fleet_diagnose_decimates_as_servo_diagnose_does_by_default():
    p = build_parser()
    single = p.parse_args(["diagnose", "r.npz"])
    fleet = p.parse_args(["fleet", "diagnose", "r.npz"])
    assert fleet.decimate == single.decimate

    from servo.cli.diagnose import parse_decimate
    from servo.diagnose.job import Options

    rule, q = parse_decimate(fleet.decimate)
    opt = fleet_diagnose.options(fleet_diagnose.settings(decimate=q, band=rule))
    assert opt == Options()  # servo diagnose's defaults: the decimation chosen from the recording
    fixed = fleet_diagnose.options(fleet_diagnose.settings(decimate=6, cutoff_hz=900.0))
    assert (fixed.settings.decimate, fixed.settings.cutoff_hz) == (6, 900.0)


# ---------------------------------------------------------------- what the user sees while it runs


def test_dask_records_and_warnings_go_to_the_log_not_to_stderr(tmp_path, capfd):
    import logging
    import warnings

    from servo.fleet.runner import dask_logs

    before = logging.getLogger("distributed").handlers[:]
    with dask_logs(tmp_path / "dask.log"):
        logging.getLogger("distributed.scheduler").warning("Port 8787 is already in use")
        warnings.warn("Creating scratch directories is taking a surprisingly long time", UserWarning)
    assert capfd.readouterr().err == ""
    text = (tmp_path / "dask.log").read_text()
    assert "Port 8787 is already in use" in text and "scratch directories" in text and "UserWarning" in text
    assert logging.getLogger("distributed").handlers == before  # restored


class _FakeClient:
    def __init__(self, services):
        self.services, self.dashboard_link = services, "http://127.0.0.1:40123/status"

    def scheduler_info(self):
        return {"services": self.services, "workers": {}}


def test_the_dashboard_link_is_said_on_stderr_as_soon_as_the_cluster_is_up():
    import io

    from servo.fleet.runner import Progress
    from servo.io.progress import QUIET, Reporter

    stream = io.StringIO()
    p = Progress(Reporter("servo fleet diagnose", stream=stream, tty=False, thread=False), 10)
    p.connected(_FakeClient({"dashboard": 40123}))
    p.connected(_FakeClient({}))
    assert stream.getvalue().splitlines() == [
        "servo fleet diagnose: Dask dashboard at http://127.0.0.1:40123/status",
        "servo fleet diagnose: no Dask dashboard (it needs bokeh: pip install 'servo-vcm[dashboard]')"]  # fmt: skip
    Progress(QUIET, 10).connected(_FakeClient({"dashboard": 1}))  # --quiet: nothing, and no error


def _time_left_at_half_way(n_drives: int, workers: int, seed: int, batch: int = 1, spread: float = 0.5
                           ) -> tuple[float, float]:  # fmt: skip
    """A fleet of ``n_drives`` on ``workers`` workers, simulated on a fake clock: each
    worker starts (imports, kernels) in 4-6 s, then runs batches of ``batch`` drives of
    1 +- ``spread`` s each, one after the other; the time left the progress line says
    when half the drives are done, and the time the rest took."""
    import heapq
    import re

    import numpy as np

    from servo.fleet.runner import Progress
    from servo.io.progress import Reporter

    rng = np.random.default_rng(seed)
    now = [0.0]
    reporter = Reporter("servo fleet diagnose", stream=open(os.devnull, "w"), tty=False, thread=False,
                        clock=lambda: now[0])  # fmt: skip
    p = Progress(reporter, n_drives)
    p.connected(_FakeClient({}))  # the count of workers
    p.workers = workers
    start = 5.0 + (rng.uniform(-1.0, 1.0, workers) if spread else np.zeros(workers))
    free = [(float(start[w]), w) for w in range(workers)]
    done_at = []
    for _ in range(0, n_drives, batch):
        t, w = heapq.heappop(free)
        end = t + float(rng.uniform(1.0 - spread, 1.0 + spread, batch).sum())
        done_at.append(end)
        heapq.heappush(free, (end, w))
    said = None
    for k, t in enumerate(sorted(done_at)):
        now[0] = t
        p([{"error": None}] * batch)
        if said is None and (k + 1) * batch >= n_drives / 2:
            said = float(re.search(r"~([\d.]+) s left", reporter.line()[0]).group(1))
            half = t
    return said, max(done_at) - half


@pytest.mark.parametrize("n_drives,workers,batch,spread", [
    (8, 2, 1, 0.0),  # 8 drives of 1 s on 2 workers started together: the first rate counted 3 drives in 1 s
    (40, 2, 1, 0.5), (40, 4, 1, 0.5), (200, 2, 4, 0.5)])  # fmt: skip
def test_the_time_left_is_within_30_percent_by_the_half_way_point(n_drives, workers, batch, spread):
    for seed in range(5):
        said, took = _time_left_at_half_way(n_drives, workers, seed, batch, spread)
        assert abs(said - took) <= 0.3 * took, (seed, said, took)


def test_a_synthetic_fleet_on_a_full_disk_is_one_line_naming_the_folder_and_leaves_nothing(tmp_path, capsys,
                                                                                          monkeypatch):  # fmt: skip
    import servo.fleet.synthetic as synthetic_mod

    def full(*a, **k):  # what numpy raises writing into a full file system: no file named
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(synthetic_mod.np, "savez", full)
    out = tmp_path / "syn"
    assert main(["fleet", "synthetic", "--drives", "2", "--duration", "0.05", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    # one line naming where it was writing (the staging folder, or the file in it)
    assert err.startswith(f"servo: error: {out}.incomplete") and err.count("\n") == 1, err
    assert "No space left on device" in err, err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("duration", ["1e6", "-1", "nan"])
def test_a_synthetic_recording_longer_than_a_recording_may_hold_is_one_line(tmp_path, capsys, duration):
    """A length the readers would refuse (or none) is refused before anything is simulated:
    1e6 s at 50 kHz asked for 5e10 samples."""
    out = tmp_path / "syn"
    assert main(["fleet", "synthetic", "--drives", "2", "--duration", duration, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("servo: error: --duration") and err.count("\n") == 1 and "per recording" in err, err
    assert not list(tmp_path.iterdir())


def test_the_table_and_fleet_json_carry_the_provenance_and_the_units(recs, tmp_path, capsys):
    """fleet.json and the Parquet schema hold the same provenance (version, commit, the
    command line, the libraries), and the schema each column's unit.  (Before: the
    table's schema had no metadata and fleet.json only the versions.)"""
    import json

    from servo.fleet.table import units_of

    d, _ = recs
    code, out, err = _identify([str(d / "drive*.npz"), "--out", str(tmp_path / "a")], capsys)
    assert code == 0, err
    summary = json.loads((tmp_path / "a" / "fleet.json").read_text())
    prov = summary["provenance"]
    assert prov["servo_version"] and prov["source"]["commit"] and prov["libraries"]["pyarrow"] and prov["libraries"]["dask"]
    md = pq.read_schema(tmp_path / "a" / "fleet.parquet").metadata
    assert json.loads(md[b"servo.provenance"]) == prov
    units = json.loads(md[b"servo.units"])
    assert units["J"] == units["J_std"] == "A*s^2/m" and units["B"] == "A*s/m" and units["Fc"] == "A"
    assert units["sample_rate_hz"] == "Hz"
    cols = ["inertia.J", "hysteresis.sigma_std", "hysteresis.dahl_length", "test_force_rel_pct_after", "error_rms_m",
            "settling_ms", "drive", "verdict"]  # fmt: skip
    assert units_of(cols, "N") == {"inertia.J": "N*s^2/m", "hysteresis.sigma_std": "N/m", "hysteresis.dahl_length": "m",
                                   "test_force_rel_pct_after": "%", "error_rms_m": "m", "settling_ms": "ms"}  # fmt: skip

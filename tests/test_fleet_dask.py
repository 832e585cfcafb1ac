"""``servo fleet diagnose`` on Dask: a synthetic fleet with known defects on a local
cluster of 2 workers, and on a real ``dask scheduler`` with two ``dask worker``
processes on 127.0.0.1, one of them killed mid-run.  Each table must equal the serial
run's, row for row, and name exactly the defective drives."""
import json
import os
import signal
import subprocess
import sys
import time

import pyarrow.parquet as pq
import pytest

from servo.fleet import diagnose as fleet_diagnose
from servo.fleet.job import run_fleet
from servo.fleet.runner import Where, dashboard_link
from servo.fleet.sources import recording_tasks, sources
from servo.fleet.synthetic import DEFECTS, synthetic_drives, write_fleet

pytestmark = pytest.mark.slow  # a cluster, a scheduler and 8 diagnoses of 1 s recordings: minutes under load

N_DRIVES, N_DEFECTS = 8, 4  # one of each defect kind, four drives without
DURATION_S = 1.0  # the concealed-effect scenario's length (the asymmetric friction needs it)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """The synthetic fleet, its tasks, and the table of the serial loop (this process)."""
    d = tmp_path_factory.mktemp("synthetic")
    drives = synthetic_drives(N_DRIVES, N_DEFECTS, seed=11)
    manifest = write_fleet(d, drives, DURATION_S)
    s = fleet_diagnose.settings()
    tasks = recording_tasks(sources([], str(manifest)), s)
    run_fleet("diagnose", tasks, s, d / "serial", Where(workers=0), plots=False)
    truth = {sd.name: sd.defect for sd in drives}
    return tasks, s, pq.read_table(d / "serial" / "fleet.parquet"), truth


def test_the_serial_loop_names_exactly_the_defective_drives_and_their_defects(fleet):
    _, _, serial, truth = fleet
    assert sorted(d for d in truth.values() if d) == sorted(DEFECTS)
    for r in serial.to_pylist():
        assert r["status"] == "ok", r["error"]
        defect = truth[r["drive"]]
        assert r["flagged"] == (defect is not None), (r["drive"], defect, r["findings"])
        assert r["findings"] == (defect or "")


class _Watch:
    """A fleet's progress callback that opens the dashboard it is told about."""

    def __init__(self):
        self.rows, self.pages = 0, []

    def __call__(self, rows):
        self.rows += len(rows)

    def connected(self, client):
        import urllib.request

        link = dashboard_link(client)
        with urllib.request.urlopen(link, timeout=30) as page:
            self.pages.append((link, page.status))


def test_a_local_cluster_of_two_workers_gives_the_serial_table_row_for_row(fleet, tmp_path, capfd):
    tasks, s, serial, truth = fleet
    watch = _Watch()
    summary = run_fleet("diagnose", tasks, s, tmp_path / "out", Where(workers=2), progress=watch)
    tmp_path = tmp_path / "out"
    assert summary["ran_on"] == "a local Dask cluster of 2 worker processes"
    assert watch.rows == N_DRIVES
    # the dashboard (the 'dashboard' extra, in the test extra too): a live page at the link given
    assert len(watch.pages) == 1 and watch.pages[0][0].startswith("http://") and watch.pages[0][1] == 200
    assert "distributed" not in capfd.readouterr().err  # Dask's records went to the log
    table = pq.read_table(tmp_path / "fleet.parquet")
    assert table.equals(serial)
    assert sorted(summary["flagged"]) == sorted(n for n, d in truth.items() if d)
    report = (tmp_path / "fleet_report.md").read_text()
    assert f"## Flagged drives ({N_DEFECTS} of {N_DRIVES})" in report
    assert {"findings.png", "histograms.png", "scatter.png"} <= {p.name for p in tmp_path.iterdir()}


def _spawn(args, log):
    return subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)  # fmt: skip


def _wait_for(path, seconds=60.0):
    t0 = time.monotonic()
    while not path.exists() or not path.read_text().strip():
        if time.monotonic() - t0 > seconds:
            raise TimeoutError(f"{path} did not appear")
        time.sleep(0.1)


def test_a_real_scheduler_loses_nothing_when_a_worker_is_killed_mid_run(fleet, tmp_path):
    from distributed import Client

    tasks, s, serial, _ = fleet
    sched_file = tmp_path / "scheduler.json"
    log = open(tmp_path / "dask.log", "wb")
    procs = [_spawn(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", str(sched_file)], log)]  # fmt: skip
    try:
        _wait_for(sched_file)
        address = json.loads(sched_file.read_text())["address"]
        for name in ("w0", "w1"):
            procs.append(_spawn(["worker", "--scheduler-file", str(sched_file), "--nthreads", "1", "--no-nanny",
                                 "--no-dashboard", "--name", name, "--host", "127.0.0.1"], log))  # fmt: skip
        watch = Client(address, timeout=30)
        watch.wait_for_workers(2, timeout=60)
        by_name = {info["name"]: addr for addr, info in watch.scheduler_info()["workers"].items()}
        killed = {}

        def kill_a_busy_worker(rows):
            if killed:
                return
            busy = watch.processing()
            for i, name in ((1, "w0"), (2, "w1")):
                if busy.get(by_name[name]):
                    killed.update(name=name, tasks=list(busy[by_name[name]]))
                    os.kill(procs[i].pid, signal.SIGKILL)
                    return

        summary = run_fleet("diagnose", tasks, s, tmp_path / "out", Where(scheduler=address), plots=False,
                            progress=kill_a_busy_worker)  # fmt: skip
        assert killed["tasks"], "the killed worker was running a task"
        victim = procs[1 if killed["name"] == "w0" else 2]
        assert victim.wait(timeout=10) == -signal.SIGKILL
        assert summary["ok"] == N_DRIVES and summary["ran_on"] == f"the Dask cluster at {address}"
        assert pq.read_table(tmp_path / "out" / "fleet.parquet").equals(serial)
        assert len(watch.scheduler_info()["workers"]) == 1  # the survivor ran the killed worker's tasks
        watch.close()
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
        log.close()


#: a controller plug-in that, in a Dask worker process only, warns, logs and prints when
#: loaded and on every configure: what a user's module or a library may do in a task
NOISY = '''
import logging
import multiprocessing
import warnings

import numpy as np

from servo.controllers.pi import PI


def noise():
    if multiprocessing.parent_process() is not None:  # a worker, not the command's process
        warnings.warn("noisy: a warning raised in a worker", UserWarning)
        np.log(np.zeros(1))  # numpy's own RuntimeWarning
        logging.getLogger("noisy").warning("noisy: a log record in a worker")
        print("noisy: printed by a worker")


noise()


class Noisy(PI):
    name = "noisy"
'''


def test_fleet_on_a_local_cluster_prints_only_its_own_lines(tmp_path):
    """``servo fleet simulate`` on a local cluster of 2 workers whose tasks warn, log
    and print (a plug-in loaded in each worker): stderr holds nothing but the command's
    own progress lines, stdout nothing but its summary; all the workers wrote is in
    ``dask.log``.  (Before: the workers, which inherit the command's descriptors, wrote
    their warnings and prints between its lines.)"""
    (tmp_path / "noisy.py").write_text(NOISY)
    out = tmp_path / "fleet"
    r = subprocess.run([sys.executable, "-m", "servo", "fleet", "simulate", "--plugin", "noisy",
                        "--set", "controller.kind=noisy", "--vary", "drive.B=normal(2e-3, 20%)", "--drives", "6", "--duration", "0.05", "--workers", "2",
                        "--no-plots", "--out", str(out)], cwd=tmp_path, capture_output=True, text=True,
                       timeout=900)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "noisy" not in r.stderr and "Warning" not in r.stderr, r.stderr
    assert all(line.startswith("servo fleet simulate: ") for line in r.stderr.splitlines()), r.stderr
    assert "noisy" not in r.stdout and r.stdout.startswith("servo fleet simulate: 6 drives, 6 ok"), r.stdout
    assert "a local Dask cluster of 2 worker processes" in r.stdout
    log = (out / "dask.log").read_text()
    for said in ("noisy: a warning raised in a worker", "RuntimeWarning: divide by zero", "noisy: printed by a worker"):
        assert said in log, log
    assert "dask.log" in json.loads((out / "fleet.json").read_text())["files"]


def _closed_loop_loaded(batch):
    """In a worker: whether the simulate fleet's closed loop (its kernels) was loaded
    before this batch ran."""
    return ["servo.fleet.closedloop" in sys.modules for _ in batch]


def test_the_workers_of_a_local_cluster_load_the_kernels_before_their_first_batch():
    """A local cluster's workers import what the command's adapter names (``WARM``) as
    they join, so their first batch finds the kernels loaded; without it they do not."""
    from servo.fleet import simulate
    from servo.fleet.runner import map_batches, warm_modules

    assert warm_modules("simulate") == ("servo.fleet.simulate", *simulate.WARM)
    warm = map_batches(_closed_loop_loaded, list(range(8)), Where(workers=1), warm=warm_modules("simulate"))
    cold = map_batches(_closed_loop_loaded, list(range(8)), Where(workers=1))
    assert warm == [True] * 8
    assert cold[0] is False

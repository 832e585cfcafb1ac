"""Run logs: streamed in blocks in constant memory; nothing recorded is lost; no half files."""
import json
import re
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from servo.io.runlog import RunLog, finalise_journal, read_journal


def _fill(log, rows):
    for i in range(rows):
        log.data[log.rows] = (i * 0.1, np.pi * i)
        log.rows += 1
        log.maybe_flush()


def test_blocks_reach_the_journal_during_the_run_and_finalise_atomically(tmp_path):
    cols = ("t", "x")
    log = RunLog(tmp_path, "log", cols, meta={"seed": 3}, block_rows=10)
    _fill(log, 25)
    log._writer.todo.join()  # the writer thread has synced what it was handed
    got_cols, rows, meta = read_journal(tmp_path / "log.journal")
    assert got_cols == cols and rows.shape == (20, 2) and meta == {"seed": 3}  # two full blocks
    assert log.data.shape[0] == 10 + 1024  # one block (and headroom) in memory, whatever the length
    chunks = []
    log.finalise([chunks.append])
    npz = np.load(tmp_path / "log.npz")
    expect = np.column_stack([np.arange(25) * 0.1, np.pi * np.arange(25)])
    assert np.array_equal(np.column_stack([npz["t"], npz["x"]]), expect)
    assert json.loads(str(npz["meta"])) == {"seed": 3, "rows": 25}
    csv = np.loadtxt(tmp_path / "log.csv", delimiter=",", skiprows=1)
    assert np.array_equal(csv, expect)  # %.17g: exact round trip
    assert np.array_equal(np.concatenate(chunks), expect)  # the consumers saw every row, in order
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "log.npz"]


def test_the_streamed_npz_is_what_numpy_savez_writes(tmp_path):
    rng = np.random.default_rng(0)
    data = rng.standard_normal((70_000, 3))  # more than one read-back chunk
    log = RunLog(tmp_path, "a", ("p", "q", "r"), block_rows=4096, formats=("npz",))
    for row in data:
        log.data[log.rows] = row
        log.rows += 1
        log.maybe_flush()
    log.close()
    ours = np.load(tmp_path / "a.npz")
    np.savez(tmp_path / "b.npz", p=data[:, 0], q=data[:, 1], r=data[:, 2])
    ref = np.load(tmp_path / "b.npz")
    for c in "pqr":
        assert ours[c].dtype == ref[c].dtype and np.array_equal(ours[c], ref[c])
    assert not (tmp_path / "a.csv").exists()


def test_a_journal_left_by_a_kill_is_finalised_later(tmp_path):
    log = RunLog(tmp_path, "k", ("t", "x"), block_rows=10)
    _fill(log, 30)
    log.flush()
    with open(log.journal_path, "ab") as fh:
        fh.write(b"\x00" * 12)  # a row cut by the kill
    written = finalise_journal(log.journal_path)
    assert [p.name for p in written] == ["k.npz", "k.csv"] and not log.journal_path.exists()
    assert np.load(tmp_path / "k.npz")["t"].shape == (30,)


def _start_run(tmp_path, *extra, rows=2 * 8192, preexec_fn=None):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "servo", "run", "--duration", "30", "--compensation", "on", "--quiet", "--out", str(out),
           *extra]  # --quiet: the test reads stderr's one error line, not the progress
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=preexec_fn)
    journal = tmp_path / "run.incomplete" / "log_compensated.journal"
    deadline = time.time() + 60
    while time.time() < deadline:  # wait until at least two blocks are on disk
        if journal.exists() and journal.stat().st_size > rows * 8 * 12:
            return proc, out
        time.sleep(0.05)
    proc.kill()
    raise AssertionError("the run never journalled a block")


def test_a_hard_kill_loses_at_most_the_blocks_not_yet_synced(tmp_path):
    proc, out = _start_run(tmp_path, "--fast")
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    staging = tmp_path / "run.incomplete"
    cols, rows, _ = read_journal(staging / "log_compensated.journal")
    assert rows.shape[0] >= 2 * 8192  # the blocks synced before the kill
    np.testing.assert_array_equal(rows[:, cols.index("tick")], np.arange(rows.shape[0]))
    assert not out.exists()  # the folder asked for appears only complete
    assert not any(p.name.endswith((".npz", ".csv")) for p in staging.iterdir())  # no half-written outputs
    r = subprocess.run([sys.executable, "-m", "servo", "recover", str(staging / "log_compensated.journal")],
                       capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert np.load(staging / "log_compensated.npz")["tick"].shape == (rows.shape[0],)


@pytest.mark.parametrize("sigint", ["default", "ignored at start"])
def test_ctrl_c_stops_cleanly_and_keeps_everything(tmp_path, sigint):
    """Also for a run started in a script's background, whose shell hands it an ignored
    SIGINT (seen: a test suite run in the background got exit 0 after the whole run)."""
    ignore = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if sigint != "default" else None
    proc, out = _start_run(tmp_path, preexec_fn=ignore)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    staging = tmp_path / "run.incomplete"
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"servo: interrupted; recorded data kept in {staging}/"), err
    npz = np.load(staging / "log_compensated.npz")
    n = npz["tick"].shape[0]
    assert n >= 2 * 8192
    np.testing.assert_array_equal(npz["tick"], np.arange(n))
    assert sorted(p.name for p in staging.iterdir()) == ["config.toml", "log_compensated.csv", "log_compensated.npz"]
    assert not out.exists()


def test_a_ctrl_c_inside_a_block_hand_over_neither_loses_nor_doubles_a_block(tmp_path):
    """Seen under load: Ctrl-C landed after a block was queued and before the log reset
    its row count, so the closing flush queued it again and the log held it twice."""
    log = RunLog(tmp_path, "l", ("tick",), block_rows=4, headroom=0)
    for k in range(6):
        if log.rows == 4:
            # the hand-over, interrupted right after it queued the block
            log._writer.todo.put((log.data, log.rows, log.total))
            break
        log.data[log.rows, 0] = k
        log.rows += 1
    log.close()  # the closing flush hands the same block over again
    _, rows, _ = read_journal(tmp_path / "l.journal") if (tmp_path / "l.journal").exists() else (None, None, None)
    got = np.load(tmp_path / "l.npz")["tick"] if rows is None else rows[:, 0]
    np.testing.assert_array_equal(got, [0, 1, 2, 3])


@pytest.mark.slow
def test_a_second_ctrl_c_during_finalisation_still_leaves_complete_files(tmp_path):
    proc, out = _start_run(tmp_path, "--fast", rows=300_000)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.3)  # finalising 300k+ rows to CSV takes seconds
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and err.count("\n") == 1, err
    staging = tmp_path / "run.incomplete"
    n = np.load(staging / "log_compensated.npz")["tick"].shape[0]
    csv = np.loadtxt(staging / "log_compensated.csv", delimiter=",", skiprows=1, usecols=0)
    assert n >= 300_000 and np.array_equal(csv, np.arange(n))
    np.testing.assert_array_equal(np.load(staging / "log_compensated.npz")["tick"], np.arange(n))
    assert not any(p.name.startswith(".") or p.suffix == ".journal" for p in staging.iterdir())


def _limit_file_size(limit):
    def preexec():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


@pytest.mark.parametrize("fast", ["--fast", "--no-fast"])
def test_a_journal_that_cannot_be_written_stops_the_run_safely(tmp_path, fast):
    """Issue 9.4: a 200 KB disk left a journal with 2045 of 8192 rows and a success."""
    out = tmp_path / "o"
    limit = 2 * 8192 * 12 * 8 + 300_000  # bytes: two blocks of 8192 rows of 12 columns and part of a third
    r = subprocess.run([sys.executable, "-m", "servo", "run", "--duration", "1", "--compensation", "on", fast, "--quiet",
                        "--out", str(out)], capture_output=True, text=True, preexec_fn=_limit_file_size(limit))  # fmt: skip
    assert r.returncode == 3, r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert r.stderr.startswith("servo: error: run log: writing ") and "File too large" in r.stderr
    assert "drive at zero current" in r.stderr and "recorded data kept in" in r.stderr
    staging = tmp_path / "o.incomplete"
    cols, rows, _ = read_journal(staging / "log_compensated.journal")  # the rows that fitted, whole
    assert rows.shape[0] > 2 * 8192 and rows.shape[0] * 12 * 8 < limit
    assert f"after {rows.shape[0]} rows" in r.stderr
    np.testing.assert_array_equal(rows[:, cols.index("tick")], np.arange(rows.shape[0]))
    assert not out.exists() and not list(staging.glob(".*"))


def test_a_run_needing_more_disk_than_there_is_is_refused_before_it_starts(tmp_path):
    out = tmp_path / "o"
    # an hour at 1 MHz, both runs, both formats: 3.6e9 rows of 12 values, ~4 PB
    r = subprocess.run([sys.executable, "-m", "servo", "run", "--duration", "3600", "--set", "run.sample_rate_hz=1e6",
                        "--out", str(out)], capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert re.search(r"the run logs: about 4\.\d+e\+03 TB|the run logs: about [\d.e+]+ \w?B of disk needed, [\d.]+ \w?B free",
                     r.stderr), r.stderr
    assert not out.exists() and not (tmp_path / "o.incomplete").exists()


PEAK = """
import resource, sys
from pathlib import Path
from servo.config import Config
from servo.run.job import run_job
cfg = Config().replace(run={{"duration_s": {d}}})
run_job(cfg, Path(sys.argv[1]), compensation="on", fast=True, log_formats=("npz",))
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


@pytest.mark.slow
def test_memory_does_not_grow_with_the_run(tmp_path):
    """Issue 9.2: ``servo run`` preallocated its whole log (23 GB for an hour)."""
    peak = {}
    for d in (8.0, 40.0):  # 0.4 M and 2 M ticks: 200 MB more if the log, inputs and tick times were held
        out = tmp_path / f"d{d:g}"
        r = subprocess.run([sys.executable, "-c", PEAK.format(d=d), str(out)], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        peak[d] = int(r.stdout.split()[-1])
        assert np.load(out / "log_compensated.npz")["t"].shape == (int(d * 50_000),)
    assert peak[40.0] - peak[8.0] < 40e6, peak  # measured: +25 MB (mostly drawing the plots' envelope)


def test_summaries_are_strict_json_a_nan_or_infinity_becomes_null(tmp_path):
    """Issue 9.5: summary.json held 'Infinity', which JSON readers refuse."""
    import json

    from servo.io.atomic import write_json

    p = tmp_path / "s.json"
    write_json(p, {"a": float("inf"), "b": [np.float64("nan"), np.float32(1.5)], "c": np.arange(2), "d": "x"})
    text = p.read_text()
    assert "Infinity" not in text and "NaN" not in text
    assert json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}")) == \
        {"a": None, "b": [None, 1.5], "c": [0, 1], "d": "x"}
    assert [q.name for q in tmp_path.iterdir()] == ["s.json"]


def test_the_current_folder_is_refused_as_an_output_folder(tmp_path):
    r = subprocess.run([sys.executable, "-m", "servo", "run", "--duration", "0.01", "--out", "."], cwd=tmp_path,
                       capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "is the current folder" in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == [] and not (tmp_path.parent / f"{tmp_path.name}.incomplete").exists()


def test_a_journal_failure_found_after_the_last_hand_over_is_the_fault_reported(tmp_path, monkeypatch):
    """The loop can run ahead of the journal's writer (the compiled loop releases the
    interpreter lock): a write that fails after the last hand-over is found when the log
    closes, where the NPZ fails on the same disk.  The journal's error is raised, and the
    journal keeps its rows."""
    import errno

    import servo.io.runlog as runlog

    log = runlog.RunLog(tmp_path, "r", ("tick", "x"), block_rows=8)

    class Full:
        def __init__(self, fh):
            self.fh = fh

        def write(self, b):
            raise OSError(errno.EFBIG, "File too large")

        def __getattr__(self, name):
            return getattr(self.fh, name)

    log._writer.fh = Full(log._writer.fh)
    log.data[:8] = 1.0
    log.rows = 8
    log.maybe_flush()  # handed over; the writer fails after it

    def npz_fails(*a, **k):
        raise OSError(errno.EFBIG, "File too large")

    monkeypatch.setattr(runlog, "finalise_journal", npz_fails)
    with pytest.raises(runlog.JournalError, match="File too large"):
        log.close()
    assert log.journal_path.exists() and not log.finalised

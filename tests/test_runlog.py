"""Run logs: written in blocks while the run goes; nothing recorded is lost; no half files."""
import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from servo.io.runlog import RunLog, read_journal


def test_blocks_reach_the_journal_during_the_run_and_finalise_atomically(tmp_path):
    cols = ("t", "x")
    log = RunLog(tmp_path, "log", cols, 100, meta={"seed": 3}, block_rows=10)
    for i in range(25):
        log.data[log.rows] = (i * 0.1, np.pi * i)
        log.rows += 1
        log.maybe_flush()
    got_cols, rows, meta = read_journal(tmp_path / "log.journal")
    assert got_cols == cols and rows.shape == (20, 2) and meta == {"seed": 3}  # two full blocks
    log.close()
    npz = np.load(tmp_path / "log.npz")
    assert npz["x"].shape == (25,) and json.loads(str(npz["meta"]))["rows"] == 25
    csv = np.loadtxt(tmp_path / "log.csv", delimiter=",", skiprows=1)
    assert np.array_equal(csv, log.recorded())  # %.17g: exact round trip
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "log.npz"]


def _start_run(tmp_path, *extra):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "servo", "run", "--duration", "30", "--compensation", "on", "--out", str(out), *extra]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    journal = out / "log_compensated.journal"
    deadline = time.time() + 60
    while time.time() < deadline:  # wait until at least two blocks are on disk
        if journal.exists() and journal.stat().st_size > 2 * 8192 * 8 * 12:
            return proc, out
        time.sleep(0.05)
    proc.kill()
    raise AssertionError("the run never journalled a block")


def test_a_hard_kill_loses_at_most_the_current_block(tmp_path):
    proc, out = _start_run(tmp_path, "--fast")
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    cols, rows, _ = read_journal(out / "log_compensated.journal")
    assert rows.shape[0] >= 2 * 8192  # the blocks flushed before the kill (a block being
    # written when the kill came may be cut, to the last whole row)
    np.testing.assert_array_equal(rows[:, cols.index("tick")], np.arange(rows.shape[0]))
    assert not any(p.name.endswith((".npz", ".csv")) for p in out.iterdir())  # no half-written outputs


def test_ctrl_c_stops_cleanly_and_keeps_everything(tmp_path):
    proc, out = _start_run(tmp_path)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert err.strip().count("\n") == 0 and "interrupted" in err and "Traceback" not in err
    npz = np.load(out / "log_compensated.npz")
    n = npz["tick"].shape[0]
    assert n >= 2 * 8192
    np.testing.assert_array_equal(npz["tick"], np.arange(n))
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith("config")) == [
        "log_compensated.csv", "log_compensated.npz"]  # fmt: skip
    assert not any(p.name.startswith(".") for p in out.iterdir())



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

"""Memory of ``servo diagnose``: bounded per sample (no full-rate intermediate kept per
candidate), and a recording too large for the machine refused in one line before
anything large is allocated."""

import numpy as np
import pytest

from servo.cli import main
from servo.diagnose import job
from servo.diagnose import model as model_mod
from servo.diagnose.concealed import Scenario, concealed_recording
from studies.memprobe import measure
from servo.errors import ServoError

SAMPLES = 200_000
#: peak extra bytes per sample of a diagnosis (decimation by 10): measured 1100 before the
#: rows stopped holding their full-rate columns, about 330 after; 366 on 2026-11-28 with
#: the rows cache bounded (which drops nothing at this length; 309 at 1e6 samples)
MAX_BYTES_PER_SAMPLE = 600

@pytest.fixture(scope="module")
def rec200k():
    rec, _ = concealed_recording("hysteresis", 2e-4, seed=1, scenario=Scenario(duration_s=SAMPLES / 50_000))
    return rec

@pytest.mark.slow
def test_peak_memory_per_sample_is_bounded(rec200k, tmp_path):
    path = tmp_path / "rec.npz"
    np.savez(path, t=rec200k.t, u=rec200k.u, x=rec200k.x)
    r = measure(path)  # a fresh process: its peak is the diagnosis's, not this session's
    per_sample = r["extra_mb"] * 2**20 / r["n"]
    assert r["findings"] == ["hysteresis"]
    assert per_sample < MAX_BYTES_PER_SAMPLE, r
    assert r["estimate_mb"] >= r["extra_mb"], r  # the up-front estimate does not undershoot

def test_estimate_is_linear_in_samples_and_rows():
    opt = job.Options()
    assert job.memory_estimate(2_000_000, opt) == pytest.approx(2 * job.memory_estimate(1_000_000, opt))
    assert job.memory_estimate(1_000_000, opt) < 1e9  # the benchmark's recording fits in well under 1 GB
    # the rows cache's share stops at its bound (reached between 3e6 and 4e6 samples)
    big = 10 * job.memory_estimate(10**7, opt) - job.memory_estimate(10**8, opt)
    assert big == pytest.approx(9 * model_mod.ROWS_BUDGET)

def test_available_memory_is_read_or_skipped():
    avail = job.available_memory()
    assert avail is None or avail > 0

def test_too_large_is_refused_before_any_work(rec200k, monkeypatch):
    monkeypatch.setattr(job, "available_memory", lambda: 1e6)

    def boom(*a, **k):
        raise AssertionError("the signals were built before the memory check")

    monkeypatch.setattr(job, "make_signals", boom)
    with pytest.raises(ServoError) as exc:
        job.diagnose(rec200k)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("diagnose: this recording")
    assert "GB are available" in msg and "shorter part" in msg

def test_unreadable_meminfo_skips_the_check(monkeypatch):
    monkeypatch.setattr(job, "available_memory", lambda: None)
    job.check_memory(10**12, job.Options())  # no error: nothing to compare with

def test_too_large_through_the_cli_is_one_line_and_writes_nothing(tmp_path, capsys, monkeypatch):
    t = np.arange(6000) * 1e-3
    u = np.sin(2 * np.pi * 0.7 * t) + 0.1 * np.sin(2 * np.pi * 13 * t)
    x = 1e-3 * np.sin(2 * np.pi * 0.7 * t - 1) + 1e-6 * np.sin(2 * np.pi * 13 * t)
    path = tmp_path / "rec.csv"
    np.savetxt(path, np.column_stack([t, u, x]), delimiter=",", header="t,u,x", comments="")
    monkeypatch.setattr(job, "available_memory", lambda: 1e3)
    out = tmp_path / "o"
    code = main(["diagnose", str(path), "--out", str(out)])
    err = capsys.readouterr().err
    assert code != 0
    assert err.count("\n") == 1 and err.startswith("servo: error: diagnose: this recording"), err
    assert "GB are available" in err
    assert not out.exists()

"""Progress on stderr (issue 12.6): what a job is doing, done/total and an ETA, rate-limited,
one updating line on a terminal, plain lines otherwise, nothing with ``--quiet``, never
on stdout, and the summary on stdout unchanged by it."""
import io
import re

import numpy as np
import pytest

import servo.io.progress as progress
from servo.cli import main
from servo.diagnose.concealed import concealed_recording
from servo.diagnose.job import diagnose
from servo.io.progress import QUIET, Reporter, current, reporting


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _reporter(tty=False, delay_s=2.0, every_s=1.0):
    clock, stream = Clock(), io.StringIO()
    return Reporter("servo x", stream, tty=tty, delay_s=delay_s, every_s=every_s, clock=clock, thread=False), clock, stream


def test_plain_lines_wait_for_the_delay_are_rate_limited_and_give_done_total_and_eta():
    r, clock, out = _reporter()
    r.stage("sweeps", 10, "points")
    clock.t = 1.0
    r.advance(1)
    assert not r.emit() and out.getvalue() == ""  # within the first 2 s: nothing
    clock.t = 3.0
    r.advance(1, "the second")  # 2/10 after 3 s; 1 item in the 2 s since the first
    assert r.emit()
    assert out.getvalue() == "servo x: sweeps 2/10 points (the second), 3.0 s, ~16 s left\n"
    clock.t = 3.5
    r.advance(1)
    assert not r.emit()  # at most one line a second
    clock.t = 4.5
    assert r.emit() and out.getvalue().splitlines()[-1].startswith("servo x: sweeps 3/10 points")
    clock.t = 6.0
    assert not r.emit()  # nothing changed: no line (until the heartbeat)
    clock.t = 4.5 + progress.HEARTBEAT_S + 0.1
    assert r.emit()  # a long stage still shows it is alive
    r.close()
    lines = out.getvalue().splitlines()
    assert lines[-1] == f"servo x: done in {clock.t:.0f} s" and len(lines) == 4


def test_a_terminal_gets_one_line_rewritten_in_place_and_cleared_at_the_end():
    r, clock, out = _reporter(tty=True, delay_s=0.0, every_s=0.5)
    r.stage("candidate terms", 4)
    for k in range(4):
        clock.t += 0.6
        r.update(k, f"term{k}")
        assert r.emit()
    text = out.getvalue()
    assert "\n" not in text and text.count("\r") == 4 and text.count("\x1b[K") == 4
    assert text.endswith("\rservo x: candidate terms 3/4 (term3), 2.4 s, ~0.6 s left\x1b[K")
    r.close()
    assert out.getvalue().endswith("\r\x1b[K")  # the summary starts on a clean line


def test_a_job_that_fails_or_is_quick_leaves_no_closing_line():
    r, clock, out = _reporter(delay_s=0.0)
    r.stage("work")
    clock.t = 1.0
    assert r.emit()
    r.close(failed=True)  # the error line follows; no "done"
    assert out.getvalue() == "servo x: work, 1.0 s\n"
    q, clock, out = _reporter()
    q.stage("work")
    clock.t = 1.0  # shorter than the delay: nothing at all, not even "done"
    q.emit()
    q.close()
    assert out.getvalue() == ""


def test_library_calls_report_to_nobody_unless_a_command_installs_a_reporter(capsys):
    assert current() is QUIET
    progress.stage("nothing to see", 3)
    assert list(progress.each([1, 2], "x")) == [1, 2]
    seen = []

    class Recording(Reporter):
        def stage(self, what, total=None, unit=""):
            seen.append((what, total))
            super().stage(what, total, unit)

    rec = Recording("servo x", io.StringIO(), thread=False)
    with reporting(rec):
        assert current() is rec
        progress.stage("a", 2)
        list(progress.each(["p", "q"], "b"))
    assert current() is QUIET and rec._closed and seen == [("a", 2), ("b", 2)]
    with pytest.raises(KeyError), reporting(QUIET):
        raise KeyError
    assert current() is QUIET
    assert capsys.readouterr() == ("", "")


def test_watch_reads_a_counter_the_job_cannot_report_itself():
    stream = io.StringIO()
    r = Reporter("servo x", stream, tty=False, delay_s=0.0, every_s=0.0)
    box = [0]
    r.stage("ticks", 100, "ticks")
    with r.watch(lambda: box[0]):
        for k in range(1, 101):
            box[0] = k
            if k in (30, 60):
                import time

                deadline = time.monotonic() + 5
                while f"{k}/100 ticks" not in stream.getvalue() and time.monotonic() < deadline:
                    time.sleep(0.005)
    r.close()
    text = stream.getvalue()
    assert "servo x: ticks 30/100 ticks" in text and "servo x: ticks 60/100 ticks" in text
    assert r.done == 100 and text.splitlines()[-1].startswith("servo x: done in")


def test_the_diagnosis_reports_its_stages_in_order():
    rec, _ = concealed_recording("hysteresis", 1e-3, seed=2)
    seen = []

    class Recording(Reporter):
        def stage(self, what, total=None, unit=""):
            seen.append(what)
            super().stage(what, total, unit)

        def update(self, done, detail=None):
            if detail:
                seen.append(f"  {detail}")
            super().update(done, detail)

    with reporting(Recording("servo diagnose", io.StringIO(), thread=False)):
        D = diagnose(rec)
    assert [f.physics for f in D.findings] == ["hysteresis"]
    stages = [s for s in seen if not s.startswith("  ")]
    assert stages[0] == "signals and the baseline fit"
    assert stages[1:3] == ["candidate terms, round 1", "candidate terms, round 2"]  # one finding, then none pays
    assert stages[-3:] == ["held-out proof", "the frequency response above the rows' band", "locate tests and the verdict"]
    first_round = seen[seen.index("candidate terms, round 1") + 1 : seen.index("candidate terms, round 2")]
    assert "  hysteresis" in first_round and len(first_round) >= 5  # each candidate term named in turn


def _mask(text: str) -> str:
    """A summary with its numbers masked (compute times differ from run to run)."""
    return re.sub(r"\d+(\.\d+)?", "#", text)


@pytest.fixture
def shown(monkeypatch):
    """Progress lines at once and at every wake of the reporter's thread."""
    monkeypatch.setattr(progress, "DELAY_S", 0.0)
    monkeypatch.setattr(progress, "EVERY_S", 0.0)


def _progress_lines(err: str, label: str) -> list[str]:
    lines = err.splitlines()
    assert lines and all(line.startswith(f"{label}: ") for line in lines), err
    assert lines[-1].startswith(f"{label}: done in "), err
    return lines


@pytest.mark.slow
def test_servo_run_reports_ticks_per_run_on_stderr_only_and_quiet_silences_it(tmp_path, capsys, shown):
    argv = ["run", "--duration", "0.5", "--no-fast", "--log-format", "npz", "--set", "run.log_every=4"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    out, err = capsys.readouterr()
    lines = _progress_lines(err, "servo run")
    runs = [m.groups() for m in (re.search(r"(\w+) run (\d+)/25000 ticks", s) for s in lines) if m]
    assert {label for label, _ in runs} == {"compensated", "uncompensated"}, err
    assert all(0 <= int(k) <= 25000 for _, k in runs)
    assert "servo run: plots" in err
    assert main([*argv, "--out", str(tmp_path / "b"), "--quiet"]) == 0
    quiet_out, quiet_err = capsys.readouterr()
    assert quiet_err == ""
    assert _mask(quiet_out.replace(str(tmp_path / "b"), "OUT")) == _mask(out.replace(str(tmp_path / "a"), "OUT"))
    assert "ticks," not in out  # no progress on stdout


def test_servo_diagnose_reports_stages_on_stderr_only_and_quiet_silences_it(tmp_path, capsys, shown):
    rec, _ = concealed_recording("hysteresis", 1e-3, seed=2)
    path = tmp_path / "r.npz"
    np.savez(path, t=rec.t, u=rec.u, x=rec.x)
    assert main(["diagnose", str(path), "--no-plots", "--out", str(tmp_path / "a")]) == 0
    out, err = capsys.readouterr()
    _progress_lines(err, "servo diagnose")
    assert "candidate terms, round 1" in err or "held-out proof" in err or "locate tests" in err, err
    assert main(["diagnose", str(path), "--no-plots", "--out", str(tmp_path / "b"), "--quiet"]) == 0
    quiet_out, quiet_err = capsys.readouterr()
    assert quiet_err == "" and quiet_out.replace("/b", "/a") == out  # the summary is unchanged, to the digit


def test_servo_fleet_reports_drives_done_and_quiet_silences_it(tmp_path, capsys, shown):
    argv = ["fleet", "simulate", "--drives", "6", "--duration", "0.1", "--workers", "0", "--no-plots",
            "--vary", "drive.sigma=normal(320, 10%)"]  # fmt: skip
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    out, err = capsys.readouterr()
    lines = _progress_lines(err, "servo fleet simulate")
    counts = [int(m.group(1)) for m in (re.search(r": (\d)/6 drives \((\d) failed\)", s) for s in lines) if m]
    assert counts and counts == sorted(counts) and max(counts) <= 6, err
    assert main([*argv, "--out", str(tmp_path / "b"), "--quiet"]) == 0
    quiet_out, quiet_err = capsys.readouterr()
    assert quiet_err == ""
    assert _mask(quiet_out.replace("/b", "/a")) == _mask(out)


def test_servo_bode_reports_frequencies_done_and_the_sweep_in_hand(tmp_path, capsys, shown):
    argv = ["bode", "--levels", "1,4", "--n-freq", "3", "--periods", "2", "--f-min", "100", "--f-max", "300",
            "--no-second-drive"]  # fmt: skip
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    out, err = capsys.readouterr()
    lines = _progress_lines(err, "servo bode")
    assert any(re.search(r"Bode sweeps \d+/12 frequencies \(sweep \d/4: drive, compensation o(n|ff)", s) for s in lines), err
    assert main([*argv, "--out", str(tmp_path / "b"), "--quiet"]) == 0
    quiet_out, quiet_err = capsys.readouterr()
    assert quiet_err == "" and quiet_out.replace("/b", "/a") == out

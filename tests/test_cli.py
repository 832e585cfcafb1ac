"""The ``servo`` command: the main job runs; bad input is one line and a non-zero exit."""
import json
import subprocess
import sys

import numpy as np
import pytest


def servo(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "servo", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.mark.slow
def test_run_writes_logs_summary_and_plots(tmp_path):
    out = tmp_path / "out"
    r = servo("run", "--duration", "0.3", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "tracking error RMS" in r.stdout and "overruns" in r.stdout
    names = {p.name for p in out.iterdir()}
    assert {"log_compensated.npz", "log_uncompensated.csv", "summary.json", "tracking.png", "steps.png",
            "current.png", "timing.png", "config.toml"} <= names  # fmt: skip
    s = json.loads((out / "summary.json").read_text())
    assert s["ticks"] == 15000
    comp, raw = s["runs"]["compensated"], s["runs"]["uncompensated"]
    # the paper's point in the time domain: with compensation the 0.3 um and the 20 um
    # steps settle alike; without, the small step drags its pivot-friction tail
    small, large = comp["steps"][0], comp["steps"][2]
    assert abs(small["settling_ms"] - large["settling_ms"]) < 2.0
    assert raw["steps"][0]["settling_ms"] > 2 * small["settling_ms"]
    assert np.load(out / "log_compensated.npz")["t"].shape == (15000,)


@pytest.mark.slow
def test_fast_path_run_matches_tick_path_run(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert servo("run", "--duration", "0.1", "--compensation", "on", "--out", str(a)).returncode == 0
    assert servo("run", "--duration", "0.1", "--compensation", "on", "--fast", "--out", str(b)).returncode == 0
    la, lb = np.load(a / "log_compensated.npz"), np.load(b / "log_compensated.npz")
    for col in ("x", "u", "h_hat"):
        assert np.array_equal(la[col], lb[col])


@pytest.mark.slow
def test_config_prints_a_loadable_documented_default(tmp_path):
    r = servo("config")
    assert r.returncode == 0 and "[drive]" in r.stdout
    f = tmp_path / "c.toml"
    f.write_text(r.stdout)
    assert servo("config", "--config", str(f), "--set", "drive.sigma=400.0").stdout.count("sigma = 400.0") == 1


@pytest.mark.parametrize(
    "args,needle",
    [
        (["run", "--set", "drive.sigmaa=1"], "unknown key 'drive.sigmaa'"),
        (["run", "--set", "drive.sigma=-5"], "drive.sigma = -5 is out of range"),
        (["run", "--set", "nonsense"], "expected section.key=value"),
        (["run", "--duration", "-1"], "run.duration_s = -1.0 is out of range"),
        (["run", "--duration", "abc"], "invalid float value"),
        (["run", "--config", "/nonexistent.toml"], "no such file"),
        (["run", "--bogus"], "unrecognized arguments: --bogus"),
        (["frobnicate"], "invalid choice"),
    ],
)
def test_bad_input_is_one_line_and_a_nonzero_exit(args, needle, tmp_path):
    r = servo(*args, "--out", str(tmp_path / "o")) if args[0] == "run" and "--bogus" not in args else servo(*args)
    assert r.returncode != 0
    assert "Traceback" not in r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("servo: error:"), r.stderr
    assert needle in r.stderr
    assert not (tmp_path / "o").exists()  # nothing written on bad input


@pytest.mark.slow
@pytest.mark.parametrize("command", [["run", "--duration", "0.01"], ["identify", "--simulate"],
                                     ["hysteresis", "--simulate"]])  # fmt: skip
@pytest.mark.parametrize("where", ["under_a_file", "on_a_file"])
def test_an_output_path_the_os_refuses_is_one_line_naming_it_and_exit_2(command, where, tmp_path):
    """The user's environment, not a bug: no 'internal error', no exit 70 (issue 9.3)."""
    blocker = tmp_path / "a-file"
    blocker.write_text("keep me")
    out = blocker / "out" if where == "under_a_file" else blocker
    r = servo(*command, "--out", str(out))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("servo: error: "), r.stderr
    assert str(blocker) in r.stderr and ("Not a directory" in r.stderr or "File exists" in r.stderr), r.stderr
    assert blocker.read_text() == "keep me"


@pytest.mark.parametrize("command", ["identify", "hysteresis", "frf", "run", "diagnose", "loop", "warmup"])
def test_every_long_command_takes_quiet(command):
    """One flag vocabulary: --quiet on every command that may print progress (identify,
    hysteresis and frf once refused it)."""
    from servo.cli import build_parser

    sub = build_parser()._subparsers._group_actions[0].choices[command]
    assert "--quiet" in sub.format_help()


@pytest.mark.slow
def test_printed_units_follow_the_recording(tmp_path):
    """A recording whose header says u [N] printed its estimates in A (J in A*s^2/m)."""
    import numpy as np

    t = np.arange(4000) * 1e-3
    x = 1e-3 * np.sin(2 * np.pi * 2 * t) + 2e-4 * np.sin(2 * np.pi * 7 * t)
    a = np.gradient(np.gradient(x, t), t)
    v = np.gradient(x, t)
    u = 2.0 * a + 5.0 * v + 0.3 * np.sign(v) + 0.01 * np.random.default_rng(0).standard_normal(t.size)
    rec = tmp_path / "rec.csv"
    np.savetxt(rec, np.column_stack([t, u, x]), delimiter=",", header="t [s],u [N],x [m]", comments="")
    r = servo("identify", str(rec), "--quiet", "--out", str(tmp_path / "id"))
    assert r.returncode == 0, r.stderr
    assert "N*s^2/m" in r.stdout and "A*s^2/m" not in r.stdout
    r = servo("frf", str(rec), "--quiet", "--out", str(tmp_path / "frf"))
    assert r.returncode == 0, r.stderr
    import json

    assert json.loads((tmp_path / "frf" / "summary.json").read_text())["unit"] == "m/N"

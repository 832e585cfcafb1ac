"""The controller interface: a kind is one module plus one registration; docs/controllers.md
is executed (its worked example saved as a module, then run on both paths)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from servo.config import Config
from servo.controllers import KINDS, ControllerKind, register

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "controllers.md"


@pytest.fixture
def kinds_restored():
    before = dict(KINDS)
    yield
    KINDS.clear()
    KINDS.update(before)


@pytest.mark.slow
def test_the_worked_example_in_the_docs_runs(tmp_path, monkeypatch, kinds_restored):
    blocks = re.findall(r"^```python\n(.*?)^```", DOC.read_text(), flags=re.S | re.M)
    assert len(blocks) >= 2
    (tmp_path / "my_pd.py").write_text(blocks[0])
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "controllers_doc"}
    for i, block in enumerate(blocks[1:], start=2):
        try:
            exec(compile(block, f"docs/controllers.md block {i}", "exec"), ns)
        except Exception as exc:
            raise AssertionError(f"docs/controllers.md block {i} failed: {type(exc).__name__}: {exc}") from exc
    log = ns["log"]
    assert list(log)[-1] == "de_dt"  # the kind's own column, after the common ones
    # the PD followed the 0.3 um step and back: 30 ms after the last, its error is well under the step
    assert np.ptp(log["r"]) >= 0.3e-6 and np.ptp(log["x"]) > 0.2e-6 and abs(log["e"][-1]) < 0.1e-6
    # and the same module through the command line, as a plugin
    r = subprocess.run([sys.executable, "-m", "servo", "run", "--plugin", "my_pd", "--set", "controller.kind=pd",
                        "--set", "run.duration_s=0.05", "--fast", "--out", str(tmp_path / "cli")],
                       capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "de_dt" in np.load(tmp_path / "cli" / "log_compensated.npz").files
    # and on a fleet's Dask workers, which load the plugin themselves
    r = subprocess.run([sys.executable, "-m", "servo", "fleet", "simulate", "--quiet", "--plugin", "my_pd",
                        "--set", "controller.kind=pd", "--vary", "drive.B=normal(2e-3, 10%)", "--drives", "4",
                        "--workers", "2", "--duration", "0.02", "--no-plots", "--out", str(tmp_path / "fleet")],
                       capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert r.returncode == 0 and "4 drives, 4 ok, 0 failed" in r.stdout, r.stdout + r.stderr


def test_a_plugin_that_is_not_there_is_one_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "servo", "run", "--plugin", "no_such_module_here", "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert "--plugin no_such_module_here: cannot import it" in r.stderr


def test_an_incomplete_kind_is_refused_at_registration(kinds_restored):
    class Half(ControllerKind):
        name = "half"
        STATE = PARAMS = np.dtype([("a", "f8")])

    with pytest.raises(TypeError, match="missing Section"):
        register(Half)
    assert "half" not in KINDS


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_kind_runs_the_same_bits_on_the_tick_and_the_fast_path(tmp_path, kind):
    from servo.runtime.closedloop import MemoryLog
    from servo.runtime.controller import Controller
    from servo.runtime.loop import log_rows, run_closed_loop
    from servo.scenarios import scenario_inputs
    from servo.runtime.simdriver import SimDriver

    cfg = Config().replace(controller={"kind": kind}, run={"duration_s": 0.06})
    logs = []
    for fast in (False, True):
        ctl = Controller(cfg)
        log = MemoryLog(log_rows(cfg), ctl.log_columns)
        inputs = scenario_inputs(cfg)
        with SimDriver(cfg, inputs) as drv:
            run_closed_loop(cfg, drv, ctl, inputs, log, fast=fast, timing=False)
        logs.append(log.data[: log.rows])
    assert logs[0].shape == (cfg.n_ticks, len(ctl.log_columns))
    assert np.array_equal(logs[0], logs[1])
    x = logs[0][:, ctl.log_columns.index("x")]
    assert np.isfinite(logs[0]).all() and np.ptp(x) > 0.1e-6  # the loop moved (the 0.3 um step at 50 ms)


def test_a_kind_cannot_take_a_built_in_name_nor_log_other_than_its_columns(kinds_restored):
    from servo.controllers.pi import PI

    class Shadow(PI):
        pass  # name "pi", another class

    with pytest.raises(TypeError, match="name 'pi' is taken by servo.controllers.pi.PI"):
        register(Shadow)

    class TwoCols(PI):
        name = "twocols"
        log_columns, log_units = ("a", "b"), {"a": "-", "b": "-"}  # the PI's log writes none

    with pytest.raises(TypeError, match="leaves some of its 2 log_columns unwritten"):
        register(TwoCols)
    assert KINDS["pi"] is PI and "twocols" not in KINDS


@pytest.mark.slow
def test_a_plugin_that_fails_and_a_design_that_cannot_be_are_one_line_before_any_output(tmp_path):
    (tmp_path / "bad_raise.py").write_text("raise RuntimeError('boom')\n")
    cases = [
        (["--plugin", "bad_raise"], "--plugin bad_raise: cannot import it (RuntimeError: boom)"),
        (["--set", "controller.kind=track", "--set", "controller.track.phase_margin_deg=85"], "is out of reach"),
        (["--set", "controller.kind=track", "--set", "controller.track.delay_s=0.0009"], "is unstable on the double integrator"),
    ]  # fmt: skip
    for i, (args, message) in enumerate(cases):
        out = tmp_path / f"o{i}"
        r = subprocess.run([sys.executable, "-m", "servo", "run", *args, "--out", str(out)],
                           capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and message in r.stderr, r.stderr
        assert not out.exists() and not (tmp_path / f"o{i}.incomplete").exists()


@pytest.mark.parametrize("track, message", [
    ({"peak_hz": [120.0]}, "controller.track.peak_hz, peak_gain_db, peak_width and peak_phase_deg must have the same length"),
    ({"peak_hz": [30000.0], "peak_gain_db": [6.0], "peak_width": [0.1], "peak_phase_deg": [0.0]},
     "controller.track.peak_hz[0] = 30000.0 is at or above the Nyquist frequency"),
    ({"peak_hz": [120.0 * k for k in range(1, 9)], "peak_gain_db": [6.0] * 8, "peak_width": [0.01] * 8,
      "peak_phase_deg": [0.0] * 8}, "at most 7 peak filters"),
    ({"peak_hz": [120.0], "peak_gain_db": [6.0], "peak_width": [0.01], "peak_phase_deg": [95.0]}, "peak_phase_deg[0]"),
])  # fmt: skip
def test_track_peak_filters_are_checked(track, message):
    from servo.config import Config
    from servo.errors import ConfigError

    with pytest.raises(ConfigError, match=re.escape(message)):
        Config().replace(controller={"kind": "track", "track": track})


def test_track_peak_filters_join_the_pes_rate_cascade():
    from servo.config import Config
    from servo.controllers import get_kind

    peaks = {"peak_hz": [120.0, 240.0], "peak_gain_db": [20.0, 12.0], "peak_width": [0.01, 0.01], "peak_phase_deg": [0.0, 0.0]}
    for extra, n in (({}, 1), (peaks, 3)):
        cfg = Config().replace(controller={"kind": "track", "track": extra})
        p = get_kind("track").params(cfg.controller.section, cfg)
        assert int(p["n_slow"][0]) == n

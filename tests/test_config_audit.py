"""No silently ignored settings: every config field, set to a value other than its
default, changes what a run does or is refused with one line saying why; the few that act
only on a board or on another path name the module that reads them.

And ``[compensator] enabled = false`` acts on ``servo run`` and ``servo loop``: their
default follows it, and asking for the compensator it turns off is one line."""
from __future__ import annotations

import dataclasses
import importlib
import inspect
import json
from pathlib import Path

import numpy as np
import pytest

from servo.config import SECTIONS, Config, documented
from servo.controllers import KINDS
from servo.errors import ConfigError, UnstableLoop
from servo.runtime.closedloop import MemoryLog
from servo.runtime.controller import Controller, compensation_runs
from servo.runtime.loop import log_rows, run_closed_loop
from servo.runtime.simdriver import SimDriver
from servo.scenarios import scenario_inputs
from tests.helpers import SHARED, run_doc_command

#: The run every field is tried on: the default scenario (steps, then the disturbance).
BASE = {"run": {"duration_s": 0.42}}

#: Fields that do not act on a simulated run, and the module that reads them.
ELSEWHERE = {
    "link.batch": "hil.serialdriver",  # the serial link's frames
    "link.timeout_s": "hil.serialdriver",
    "link.watchdog_s": "hil.serialdriver",  # sent to the board in its config message
    "link.late_limit_ticks": "hil.serialdriver",
    "link.baudrate": "hil.serialdriver",
    "run.fast_path": "servo.run.job",  # the same bits on either path, by design
    "link.ready_timeout_s": "hil.serialdriver",  # sent to the board in its config message
    "run.fault_window_s": "servo.runtime.watchdog",  # acts only on a loop saturated for part of a window
}

#: Values for fields whose automatic choice would not exercise them.
VALUE = {
    "scenario.kind": "hdd_benchmark",
    "scenario.excitation": "chirp",
    "scenario.disturbance_start": 0.2,
    "scenario.excitation_start": 0.1,
    "drive.initial_position": 1e-3,
    "drive.stroke": 0.5e-6,
    "drive.current_limit": 2e-3,
    "controller.current_limit": 2e-3,
    "compensator.authority": 1e-4,
    "compensator.periodic_amplitudes": [1e-4],
    "compensator.periodic_phases": [0.5],
    "compensator.fast_on_speed": 0.05,
    "compensator.kf_authority": 0.05,
    "controller.pi.holding_limit": 2e-3,
    "run.fault_position": 1e-5,  # inside the 20 um step: the run stops
    "run.fault_limit_share": 0.65,
    "scenario.hdd_package": str(SHARED / "data" / "nss-hdd-benchmark"),
}

#: Fields that can only change together with another (lists of the same length).
CHANGE = {"compensator.periodic_amplitudes": {"compensator": {"periodic_amplitudes": [1e-4], "periodic_phases": [0.0]}}}

#: What a changed field needs beside it to act (its companion switched on).
WITH = {
    "link.loop": {"link": {"command_latency_ticks": 2}},  # on the board, the link's latency leaves the loop
    "scenario.hdd_version": {"scenario": {"kind": "hdd_benchmark"}, "run": {"sample_rate_hz": 52800.0}},
    "scenario.excitation_amplitude": {"scenario": {"excitation": "chirp"}},
    "scenario.excitation_f_min": {"scenario": {"excitation": "chirp"}},
    "scenario.excitation_f_max": {"scenario": {"excitation": "chirp"}},
    "scenario.excitation_period": {"scenario": {"excitation": "multisine"}},
    "scenario.excitation_start": {"scenario": {"excitation": "chirp"}},
    "drive.cogging_period": {"drive": {"cogging": 1e-4}},
    "drive.cogging_phase": {"drive": {"cogging": 1e-4}},
    "drive.stribeck_velocity": {"drive": {"Fs": 2e-3}},
    "compensator.stribeck_velocity": {"compensator": {"coulomb_extra": 1e-3, "coulomb_static": 2e-3}},
    "compensator.coulomb_asymmetry": {"compensator": {"coulomb_extra": 1e-3}},
    "compensator.periodic_phases": {"compensator": {"periodic_amplitudes": [1e-4], "periodic_phases": [0.0]}},
    "compensator.periodic_period": {"compensator": {"periodic_amplitudes": [1e-4], "periodic_phases": [0.0]}},
    "compensator.kf_stroke": {"compensator": {"kf_linear": 0.2}},
    "compensator.kf_authority": {"compensator": {"kf_linear": 0.5}, "scenario": {"step_positions": [0.3e-6, 0.0, 5e-3, 0.0]}},
    "run.excitation_every": {"scenario": {"excitation": "chirp"}},
    "drive.fc_asymmetry": {"drive": {"Fc": 1e-3, "Fs": 1e-3}},
    "controller.velocity_cutoff_hz": {"controller": {"velocity_source": "estimated"}},
    "drive.velocity_noise": {"controller": {"velocity_source": "auto"}},
    "run.fault_limit_share": {"controller": {"current_limit": 2e-3}, "run": {"fault_limit_share": 1.0}},
    "scenario.hdd_package": {"scenario": {"kind": "hdd_benchmark"}, "run": {"sample_rate_hz": 52800.0}},
}


def other_value(f: dataclasses.Field, default):
    """A valid value other than ``default`` for a :func:`~servo.config.P` field."""
    m = f.metadata
    if isinstance(default, bool):
        return not default
    if isinstance(default, str):
        choices = m["choices"]() if callable(m["choices"]) else m["choices"]
        return next(c for c in choices if c != default)
    if isinstance(default, list):
        return [v * 1.3 for v in default] if default else [1e-4]
    hi = m["hi"]
    if isinstance(default, int):
        v = default + 1
    else:
        v = default * 1.3 if default else (hi / 2 if hi is not None else 1e-3)
    if hi is not None and v > hi:
        v = default * 0.7 if isinstance(default, float) else default - 1
    return v


def fields_to_audit():
    out = []
    for name, cls in SECTIONS.items():
        default = getattr(Config(), name)
        for f in documented(cls):
            out.append((f"{name}.{f.name}", f, getattr(default, f.name), None))
    for kind, k in KINDS.items():
        section = k.Section()
        for f in documented(type(section)):
            out.append((f"controller.{kind}.{f.name}", f, getattr(section, f.name), kind))
    return out


def _log(cfg: Config) -> np.ndarray:
    """The run's log, then its on-line error estimate (``servo run``'s summary) as a row."""
    inputs = scenario_inputs(cfg)
    controller = Controller(cfg)
    log = MemoryLog(log_rows(cfg), controller.log_columns)
    with SimDriver(cfg, inputs) as driver:
        result = run_closed_loop(cfg, driver, controller, inputs, log, fast=True, timing=False)
    estimate = np.full((1, log.data.shape[1]), result.error_rms)
    return np.vstack([log.data[: log.rows], estimate])


def _merge(a: dict, b: dict) -> dict:
    out = {k: dict(v) for k, v in a.items()}
    for k, v in b.items():
        out.setdefault(k, {}).update(v)
    return out


AUDIT = fields_to_audit()
#: Fields the audit finds acting on nothing, kept as known defects (strict: fixing one fails
#: its xfail, so that the entry is removed).
KNOWN: dict[str, str] = {}
PARAMS = [pytest.param(*a, id=a[0], marks=pytest.mark.xfail(strict=True, reason=KNOWN[a[0]])) if a[0] in KNOWN
          else pytest.param(*a, id=a[0]) for a in AUDIT]  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("key, f, default, kind", PARAMS)
def test_every_config_field_acts_or_is_refused_with_a_reason(key, f, default, kind):
    if key in ELSEWHERE:
        source = inspect.getsource(importlib.import_module(ELSEWHERE[key]))
        assert f.name in source, f"{key}: {ELSEWHERE[key]} does not read it"
        return
    value = VALUE[key] if key in VALUE else other_value(f, default)
    section, _, name = key.partition(".")
    base = _merge(BASE, WITH.get(key, {}))
    if kind is not None:
        base = _merge(base, {"controller": {"kind": kind}})
        change = {"controller": {kind: {f.name: value}}}
    else:
        change = CHANGE.get(key, {section: {name: value}})
    if key == "scenario.kind":
        base = _merge(base, {"run": {"duration_s": 0.1}})
    if key in ("scenario.hdd_version", "scenario.hdd_package"):
        base = _merge(base, {"run": {"duration_s": 0.1}})
    a = _log(Config().replace(**base))
    try:
        changed = Config().replace(**_merge(base, change))
        b = _log(changed)
    except ConfigError as exc:  # refused: the message names the field
        assert name.split(".")[-1] in str(exc) or section in str(exc), str(exc)
        return
    except UnstableLoop:  # the change made the run stop as unstable (servo.runtime.watchdog): it acts
        return
    assert a.shape != b.shape or not np.array_equal(a, b, equal_nan=True), f"{key} = {value!r} changed nothing"


def test_compensator_disabled_is_what_servo_run_and_loop_run_by_default():
    """``[compensator] enabled = false`` (examples/hdd-nss-v2.toml) once had no effect:
    ``servo run`` compared a compensated run anyway."""
    off = Config().replace(compensator={"enabled": False})
    assert compensation_runs(off) == (False,)
    assert compensation_runs(Config()) == (True, False)
    assert compensation_runs(off, "off") == (False,)
    for asked in ("on", "compare", "both"):
        with pytest.raises(ConfigError, match="enabled = false"):
            compensation_runs(off, asked)


@pytest.mark.slow
def test_the_hdd_example_runs_uncompensated_only(tmp_path, capsys):
    code = run_doc_command(f"servo run --config examples/hdd-nss-v2.toml --duration 0.08 --log-format npz "
                           f"--out {tmp_path / 'r'}")
    assert code == 0
    out = capsys.readouterr().out
    assert "uncompensated" in out and " compensated" not in out.replace("uncompensated", "")
    assert sorted(p.name for p in (tmp_path / "r").glob("log_*")) == ["log_uncompensated.npz"]
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert list(summary["runs"]) == ["uncompensated"]
    assert summary["runs"]["uncompensated"]["estimator_error_rms_m"] > 0  # run.estimator_every's task, reported


def test_asking_for_the_disabled_compensator_is_one_line(tmp_path, capsys):
    code = run_doc_command(f"servo run --config examples/hdd-nss-v2.toml --duration 0.08 --compensation on "
                           f"--out {tmp_path / 'r'}")
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "servo: error:" in err and "enabled = false" in err
    assert not (tmp_path / "r").exists()


def test_hdd_version_selects_the_benchmarks_own_plant():
    """``scenario.hdd_version`` once changed nothing at 52.8 kHz: the two versions' parameter
    files differ only in the plant (``hdd_plantparam_v1/v2.m``; the disturbance files are the
    same), and a run's plant was the example's written-out ``[drive]``.  The scenario now
    stands for the plant of its version where the config leaves the drive at its default,
    as the examples do; a ``[drive]`` value set still wins."""
    from servo.config import load_config
    from servo.hdd.benchmark import benchmark

    root = Path(__file__).resolve().parents[1]
    v2 = load_config(root / "examples" / "hdd-nss-v2.toml")
    v1 = v2.replace(scenario={"hdd_version": 1})
    for cfg, b in ((v1, benchmark(1)), (v2, benchmark(2))):
        d = cfg.drive
        assert d.J == pytest.approx(b.m / b.Kf) and d.K == pytest.approx(b.m / b.Kf * (2 * np.pi * b.mode_hz[0]) ** 2)
        assert (d.mode_hz, d.mode_zeta, d.mode_gain) == tuple(list(map(float, a[1:])) for a in (b.mode_hz, b.mode_zeta, b.mode_gain))
        assert d.input_delay_s == b.Td and d.position_noise == pytest.approx(b.sensor_noise * b.Tp)
    assert v1.drive.J != v2.drive.J  # Kf = 0.9512 against 1.0 N/A
    back = v1.replace(scenario={"hdd_version": 2})
    assert back.drive == v2.drive
    own = v2.replace(drive={"J": 2e-3}).replace(scenario={"hdd_version": 1})  # a drive of one's own stays
    assert own.drive.J == 2e-3 and own.drive.mode_hz == v2.drive.mode_hz
    assert Config().replace(scenario={"kind": "steps"}).drive == Config().drive

"""A red-team round on every command, as a hostile user would: ``python -m studies.hostile_round DIR``.

Builds hostile inputs of each kind (config values, cross-field nonsense, recordings in
every format, model files for ``compensate``, ``--out`` paths, journals, fleets) under
``DIR`` and runs each through the command line in this process (``servo.cli.main``),
then classifies how it ended:

* ``error``: exit 2 or 3 with exactly one line ``servo: error: ...`` and nothing left in
  the output's place (no ``OUT`` or ``OUT.incomplete/`` it did not find there);
* ``result``: exit 0, the output folder complete and no ``.incomplete/`` beside it;
* ``BUG``: anything else (exit 70, more than one line, a traceback, a folder left behind),
  and ``ACCEPTED?``: exit 0 on an input marked as nonsense (to be read by a person).

It prints a count per kind and outcome, and each ``BUG``/``ACCEPTED?`` line with its
command.  The kinds that need processes of their own (Ctrl-C mid-run, two writers to one
output, the emulator) are in :mod:`studies.hostile_processes`.  docs/robustness.md gives
the counts of a round.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import shutil
import sys
from collections import Counter
from pathlib import Path

import numpy as np

#: (kind, outcome) -> count, and the lines to read.
TRIED: Counter = Counter()
FINDINGS: list[str] = []


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    from servo.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse --help and the like
            rc = exc.code if isinstance(exc.code, int) else 2
        except BaseException as exc:  # noqa: BLE001 - the round records whatever escapes
            rc = f"escaped {type(exc).__name__}: {exc}"
    return rc, out.getvalue(), err.getvalue()


def check(kind: str, argv: list, out: Path | None = None, nonsense: bool = False, expect_rc=None, judge=None,
          label: str = "") -> str:
    """Run ``argv`` and classify it (see the module docstring)."""
    existed = out is not None and out.exists()
    inc = None if out is None else out.with_name(out.name + ".incomplete")
    rc, stdout, stderr = run_cli(argv)
    lines = stderr.strip("\n").split("\n") if stderr.strip() else []
    problems = []
    if rc in (2, 3):
        if len(lines) != 1 or not lines[0].startswith("servo: error: "):
            problems.append(f"{len(lines)} stderr lines")
        if out is not None and not existed and out.exists():
            problems.append("OUT made by a refused command")
        if inc is not None and inc.exists() and not any(p.name.startswith("log_") for p in inc.iterdir()):
            problems.append(f"{inc.name}/ left: {sorted(p.name for p in inc.iterdir())[:5]}")
        outcome = "error (one line)"
    elif rc == 0:
        if inc is not None and inc.exists():
            problems.append(f"{inc.name}/ left after exit 0")
        if "Warning" in stderr:  # a library's warning printed over a result
            problems.append("a Python warning on stderr")
        outcome = "result"
        if judge is not None:
            why = judge(stdout, out)
            if why:
                nonsense, outcome = True, f"result ({why})"
        if nonsense:
            outcome = "ACCEPTED?"
    else:
        problems.append(f"exit {rc}")
        outcome = "BUG"
    if expect_rc is not None and rc != expect_rc:
        problems.append(f"exit {rc}, expected {expect_rc}")
    if problems:
        outcome = "BUG"
    TRIED[kind, outcome] += 1
    if outcome in ("BUG", "ACCEPTED?") or outcome.startswith("result ("):
        tail = (stderr.strip() if stderr.strip() else stdout.strip().split("\n")[-1] if stdout.strip() else "")[:600]
        FINDINGS.append(f"{kind} [{label}]: {outcome} {'; '.join(problems)}\n    servo {' '.join(map(str, argv))[:300]}\n    -> {tail}")
    return outcome


class Dirs:
    def __init__(self, root: Path):
        self.root = root
        self.n = 0

    def out(self) -> Path:
        self.n += 1
        return self.root / "out" / f"o{self.n}"

    def file(self, name: str) -> Path:
        self.n += 1
        d = self.root / "in" / f"i{self.n}"
        d.mkdir(parents=True, exist_ok=True)
        return d / name


# -- configs ---------------------------------------------------------------------------

BAD_VALUES = ["nan", "inf", "-inf", "1e308", "-1e308", "-1", "0", "1e-300", "'text'", "[1.0, 2.0]", "{a = 1}", "true",
              "123456789012345678901234567890", "5e-324"]  # fmt: skip


def _fields():
    from servo.config import Config, to_dict

    out = []
    for section, values in to_dict(Config()).items():
        for k, v in values.items():
            if isinstance(v, dict):  # a controller kind's own fields
                out += [(f"{section}.{k}.{kk}", vv) for kk, vv in v.items()]
            else:
                out.append((f"{section}.{k}", v))
    return out


def configs(d: Dirs, quick: bool):
    """Every field set to every value of BAD_VALUES: through ``servo config`` (the one
    validation all commands share); each accepted value that is not the default, run for
    a short time (``servo run --fast``) and its summary checked to be finite."""
    fields = _fields()
    accepted = []
    for key, default in fields:
        kind_key = key.split(".")
        for value in BAD_VALUES:
            section = kind_key[0]
            if section == "controller" and len(kind_key) == 3 and kind_key[1] != "pi":
                sets = [f"controller.kind={kind_key[1]}", f"{key}={value}"]
            else:
                sets = [f"{key}={value}"]
            argv = ["config"] + [a for s in sets for a in ("--set", s)]
            outcome = check("config value", argv)
            if outcome == "result":
                accepted.append(sets)
    # the accepted ones, run
    seen = set()
    for sets in accepted if not quick else accepted[:: max(1, len(accepted) // 60)]:  # --quick: 60 of them, spread
        if tuple(sets) in seen:
            continue
        seen.add(tuple(sets))
        out = d.out()
        argv = ["run", "--duration", "0.05", "--fast", "--compensation", "off", "--log-format", "npz", "--quiet",
                "--out", out] + [a for s in sets for a in ("--set", s)]  # fmt: skip
        check("config value, run", argv, out, judge=_judge_run)
        shutil.rmtree(out, ignore_errors=True)


def _judge_run(stdout: str, out: Path) -> str:
    try:
        s = json.loads((out / "summary.json").read_text())
    except Exception as exc:  # noqa: BLE001
        return f"no summary: {exc}"
    bad = []

    def walk(v, path):
        if isinstance(v, float) and not math.isfinite(v):
            bad.append(path)
        elif isinstance(v, dict):
            for k, x in v.items():
                walk(x, f"{path}.{k}")
        elif isinstance(v, list):
            for i, x in enumerate(v):
                walk(x, f"{path}[{i}]")

    walk(s, "")
    if bad:
        return "non-finite " + ", ".join(bad[:3])
    for name, r in (s.get("runs") or {}).items():
        e = r.get("error_max_m")
        if isinstance(e, float) and e > 0.1:  # more than a 15 mm stroke's worth of error... and then some
            return f"{name} error_max {e:.3g} m"
    return ""


CROSS = {
    "quantum = stroke": ["drive.position_quantum=0.015", "drive.stroke=0.015"],
    "noise beyond the stroke": ["drive.position_noise=1.0"],
    "J tiny, K huge": ["drive.J=1e-9", "drive.K=1e12"],
    "disturbance at Nyquist": ["scenario.disturbance_hz=25000", "scenario.disturbance_amplitude=0.01"],
    "disturbance above Nyquist": ["scenario.disturbance_hz=40000", "scenario.disturbance_amplitude=0.01"],
    "step beyond the stroke": ["scenario.step_positions=[0.0, 1.0, 0.0, 0.0]"],
    "step times not increasing": ["scenario.step_times=[0.3, 0.1, 0.2, 0.05]"],
    "steps after the run": ["scenario.step_times=[10.0, 20.0, 30.0, 40.0]"],
    "step lists of other lengths": ["scenario.step_times=[0.1]", "scenario.step_positions=[0.0, 1e-6, 0.0]"],
    "initial position beyond the stroke": ["drive.initial_position=0.5"],
    "mode above Nyquist": ["drive.mode_hz=[40000.0]", "drive.mode_zeta=[0.01]", "drive.mode_gain=[1.0]"],
    "mode lists of other lengths": ["drive.mode_hz=[4000.0, 5000.0]", "drive.mode_zeta=[0.01]"],
    "sensor cutoff above Nyquist": ["drive.sensor_cutoff_hz=40000"],
    "velocity cutoff above Nyquist": ["controller.velocity_cutoff_hz=40000"],
    "input delay longer than the run": ["drive.input_delay_s=10"],
    "controller limit above the drive's": ["controller.current_limit=100", "drive.current_limit=0.1"],
    "chirp above Nyquist": ["scenario.excitation='chirp'", "scenario.excitation_f_max=30000", "scenario.excitation_amplitude=0.01"],
    "chirp band reversed": ["scenario.excitation='chirp'", "scenario.excitation_f_min=1000", "scenario.excitation_f_max=10", "scenario.excitation_amplitude=0.01"],
    "PRBS above Nyquist": ["scenario.excitation='prbs'", "scenario.excitation_f_max=30000", "scenario.excitation_amplitude=0.01"],
    "PRBS bit beyond its period": ["scenario.excitation='prbs'", "scenario.excitation_f_max=2e-4", "scenario.excitation_amplitude=0.01"],
    "excitation after the run": ["scenario.excitation='chirp'", "scenario.excitation_start=100", "scenario.excitation_amplitude=0.01"],
    "disturbance after the run": ["scenario.disturbance_start=100", "scenario.disturbance_amplitude=0.01"],
    "excitation beyond the current limit": ["scenario.excitation='chirp'", "scenario.excitation_amplitude=50"],
    "fault window shorter than a tick": ["run.fault_window_s=1e-9"],
    "log every more than the run": ["run.log_every=100000000"],
    "estimator every more than the run": ["run.estimator_every=100000000"],
    "excitation every more than the run": ["run.excitation_every=100000000", "scenario.excitation='chirp'", "scenario.excitation_amplitude=0.01"],
    "fault position beyond the stroke": ["run.fault_position=10"],
    "cogging period zero": ["drive.cogging=0.01", "drive.cogging_period=0"],
    "stribeck velocity zero": ["drive.Fs=0.01", "drive.stribeck_velocity=0"],
    "watchdog below the timeout": ["link.watchdog_s=0.001", "link.timeout_s=5"],
    "ready timeout zero": ["link.ready_timeout_s=0"],
    "compensator K huge": ["compensator.K=1e11"],
    "compensator authority zero with terms": ["compensator.authority=0", "compensator.sliding_level=0.01"],
    "periodic lists of other lengths": ["compensator.periodic_amplitudes=[0.01, 0.02]", "compensator.periodic_phases=[0.0]"],
    "periodic period zero": ["compensator.periodic_amplitudes=[0.01]", "compensator.periodic_phases=[0.0]", "compensator.periodic_period=0"],
    "fast off above fast on": ["compensator.fast_on_speed=0.001", "compensator.fast_off_speed=1.0"],
    "track notch above Nyquist": ["controller.kind='track'", "controller.track.notch_hz=[40000.0, 7000.0, 12300.0, 16400.0]"],
    "track notch lists of other lengths": ["controller.kind='track'", "controller.track.notch_hz=[4100.0]"],
    "track crossover above Nyquist": ["controller.kind='track'", "controller.track.crossover_hz=40000"],
    "nss at another rate": ["controller.kind='nss'", "scenario.kind='hdd_benchmark'", "run.sample_rate_hz=1000"],
    "hdd benchmark, pi controller": ["scenario.kind='hdd_benchmark'"],
    "sample rate 1 Hz": ["run.sample_rate_hz=1"],
    "sample rate 1e9": ["run.sample_rate_hz=1e9"],
    "duration one tick": ["run.duration_s=2e-5"],
    "substeps huge": ["drive.substeps=1000000"],
    "quantum 1e-300": ["drive.position_quantum=1e-300"],
    "kf beyond one": ["drive.kf_linear=10", "drive.kf_quadratic=10"],
}


def cross_fields(d: Dirs):
    """Values each within its range that together make a result meaningless: each
    through ``servo run`` (a short run), and the nonsense ones judged by a person."""
    for name, sets in CROSS.items():
        out = d.out()
        argv = ["run", "--duration", "0.3", "--fast", "--compensation", "compare", "--log-format", "npz", "--quiet",
                "--out", out] + [a for s in sets for a in ("--set", s)]  # fmt: skip
        outcome = check("cross-field", argv, out, judge=_judge_run)
        if outcome == "result":
            s = json.loads((out / "summary.json").read_text())
            errs = {k: r.get("error_rms_m") for k, r in (s.get("runs") or {}).items()}
            FINDINGS.append(f"cross-field accepted (read it): {name}: error_rms {errs}")
        shutil.rmtree(out, ignore_errors=True)


# -- recordings ------------------------------------------------------------------------


def _good(n=20000, fs=10000.0, seed=0):
    """t, u, x, v of a mass-spring-damper-friction drive, simulated by Euler steps."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    u = 0.02 * np.sign(np.sin(2 * np.pi * 25 * t)) + 0.002 * rng.standard_normal(n)
    J, B, K, Fc = 1e-3, 0.05, 2.0, 0.002
    x = np.zeros(n)
    v = np.zeros(n)
    for i in range(1, n):
        a = (u[i - 1] - B * v[i - 1] - K * x[i - 1] - Fc * np.tanh(v[i - 1] / 1e-4)) / J
        v[i] = v[i - 1] + a / fs
        x[i] = x[i - 1] + v[i] / fs
    return {"t": t, "u": u, "x": x + 1e-8 * rng.standard_normal(n), "v": v}


def _write(path: Path, cols: dict, header=None):
    suffix = path.suffix
    if suffix in (".csv", ".txt"):
        names = header or list(cols)
        data = np.column_stack([np.asarray(v, float) for v in cols.values()]) if cols else np.zeros((0, len(names)))
        with open(path, "w") as fh:
            fh.write(",".join(names) + "\n")
            np.savetxt(fh, data, delimiter=",", fmt="%.10g")
    elif suffix == ".npz":
        np.savez(path, **cols)
    elif suffix in (".h5", ".hdf5"):
        import h5py

        with h5py.File(path, "w") as f:
            for k, v in cols.items():
                f[k] = v
    elif suffix == ".mat":
        from scipy.io import savemat

        savemat(path, cols)
    return path


def recording_variants(g: dict) -> dict:
    """name -> (columns dict or a writer, nonsense?)."""
    n = len(g["t"])
    v = {}
    v["good"] = (g, False)
    v["NaN in x"] = ({**g, "x": np.where(np.arange(n) == n // 2, np.nan, g["x"])}, True)
    v["inf in u"] = ({**g, "u": np.where(np.arange(n) == 7, np.inf, g["u"])}, True)
    v["all NaN u"] = ({**g, "u": np.full(n, np.nan)}, True)
    v["constant u"] = ({**g, "u": np.full(n, 0.01)}, True)
    v["constant x"] = ({**g, "x": np.full(n, 1e-3)}, True)
    v["zero u and x"] = ({**g, "u": np.zeros(n), "x": np.zeros(n)}, True)
    v["2 samples"] = ({k: a[:2] for k, a in g.items()}, True)
    v["1 sample"] = ({k: a[:1] for k, a in g.items()}, True)
    v["10 samples"] = ({k: a[:10] for k, a in g.items()}, True)
    t = g["t"].copy()
    t[n // 2:] -= 0.5
    v["time going back"] = ({**g, "t": t}, True)
    v["time reversed"] = ({k: a[::-1] for k, a in g.items()}, True)
    v["time constant"] = ({**g, "t": np.zeros(n)}, True)
    t = g["t"].copy()
    t[100] = t[99]
    v["a repeated time"] = ({**g, "t": t}, True)
    t = g["t"].copy()
    t[n // 2:] += 10.0
    v["a 10 s gap"] = ({**g, "t": t}, True)
    v["time in ms"] = ({**g, "t": g["t"] * 1e3}, True)
    v["time in us ints"] = ({**g, "t": np.arange(n) * 100}, True)
    v["x in mm"] = ({**g, "x": g["x"] * 1e3}, True)
    v["u in uA"] = ({**g, "u": g["u"] * 1e6}, True)
    v["x 1e200"] = ({**g, "x": g["x"] * 1e200}, True)
    v["u 1e-300"] = ({**g, "u": g["u"] * 1e-300}, True)
    v["x 2-D"] = ({**g, "x": np.column_stack([g["x"], g["x"]])}, True)
    v["lengths differ"] = ({**g, "x": g["x"][: n // 2]}, True)
    v["int columns"] = ({k: (a * 1e6).astype(np.int64) for k, a in g.items()}, True)
    v["bool u"] = ({**g, "u": g["u"] > 0}, True)
    v["complex x"] = ({**g, "x": g["x"] + 1j}, True)
    v["no u"] = ({k: a for k, a in g.items() if k != "u"}, True)
    v["no columns"] = ({}, True)
    v["irregular time"] = ({**g, "t": np.cumsum(np.random.default_rng(1).uniform(0.5e-4, 1.5e-4, n))}, True)
    v["random x"] = ({**g, "x": np.random.default_rng(2).standard_normal(n)}, True)
    v["u and x swapped"] = ({**g, "u": g["x"], "x": g["u"]}, True)
    return v


TEXT_CASES = {
    "empty file": "",
    "header only": "t,u,x\n",
    "duplicate column": "t,u,x,x\n0,1,2,3\n1e-4,1,2,3\n",
    "duplicate column with units": "t [s],u [A],x [m],x [mm]\n0,1,2,3\n1e-4,1,2,3\n",
    "ragged row": "t,u,x\n0,1,2\n1e-4,1\n2e-4,1,2\n",
    "words in data": "t,u,x\n0,1,2\n1e-4,one,2\n",
    "binary junk": "\x00\x01\x02\xff",
    "only commas": ",,,\n,,,\n",
    "semicolons, decimal commas": "t;u;x\n0;1,5;2\n0,0001;1,5;2\n0,0002;1,4;2\n",
    "header of numbers": "1,2,3\n4,5,6\n",
    "nan strings": "t,u,x\n" + "".join(f"{i * 1e-4},nan,nan\n" for i in range(100)),
    "inf strings": "t,u,x\n" + "".join(f"{i * 1e-4},inf,-inf\n" for i in range(100)),
    "hex numbers": "t,u,x\n0x0,0x1,0x2\n",
    "a very long name": "t,u," + "x" * 70000 + "\n0,1,2\n",
    "a million columns header": ",".join(f"c{i}" for i in range(20000)) + "\n",
    "unicode names": "t,\u00fc,\u00df\n0,1,2\n1e-4,1,2\n",
    "quoted numbers": 't,u,x\n"0","1","2"\n"1e-4","1","2"\n',
    "a NUL in a number": "t,u,x\n0,1,2\n1e-4,1\x00,2\n",
    "CR only line ends": "t,u,x\r0,1,2\r1e-4,1,2\r",
    "trailing delimiter": "t,u,x,\n" + "".join(f"{i * 1e-4},{i % 7},{i % 3},\n" for i in range(100)),
}


def recordings(d: Dirs, g: dict):
    """Each variant in CSV, NPZ, HDF5 and MAT, through identify, diagnose, frf and hysteresis."""
    variants = recording_variants(g)
    tools = {
        "identify": ["identify", "--quiet"],
        "diagnose": ["diagnose", "--no-plots", "--quiet", "--blocks", "4"],
        "frf": ["frf", "--quiet"],
        "hysteresis": ["hysteresis", "--quiet"],
    }
    for name, (cols, nonsense) in variants.items():
        for suffix in (".csv", ".npz", ".h5", ".mat"):
            path = d.file("rec" + suffix)
            try:
                if suffix == ".csv" and any(np.ndim(a) != 1 or np.iscomplexobj(a) for a in cols.values()):
                    continue  # (text has no 2-D or complex column)
                if suffix == ".csv" and len({len(a) for a in cols.values()}) > 1:
                    with open(path, "w") as fh:  # a ragged text file
                        fh.write(",".join(cols) + "\n")
                        m = max(len(a) for a in cols.values())
                        for i in range(m):
                            fh.write(",".join(repr(float(a[i])) for a in cols.values() if i < len(a)) + "\n")
                else:
                    _write(path, cols)
            except Exception as exc:  # noqa: BLE001 - a format that cannot hold it
                TRIED["recording: not writable in format", type(exc).__name__] += 1
                continue
            for tool, argv in tools.items():
                if suffix != ".csv" and tool in ("hysteresis", "frf") and name not in ("good", "NaN in x", "2 samples", "time going back", "x 2-D", "complex x"):
                    continue  # (the reader is shared: the four formats through two tools)
                out = d.out()
                check(f"recording ({tool})", argv + [path, "--out", out], out, nonsense=nonsense and name != "good",
                      label=f"{name} {suffix}")
                shutil.rmtree(out, ignore_errors=True)
    for name, text in TEXT_CASES.items():
        path = d.file("rec.csv")
        path.write_text(text, errors="surrogateescape")
        for tool in ("identify", "diagnose"):
            out = d.out()
            check(f"recording ({tool})", tools[tool] + [path, "--out", out], out, nonsense=True, label=name)
            shutil.rmtree(out, ignore_errors=True)
    # mappings and scales
    path = _write(d.file("rec.npz"), {**g, "gain": np.array(2.0), "vec": np.arange(3.0)})
    for cols, scale in [("u=x", None), ("u=nope", None), ("t=u", None), ("x=gain", None), ("u=vec", None), ("u==x", None),
                        ("", None), (",,,", None), ("q=u", None), (None, "u=0"), (None, "u=nan"), (None, "u=inf"),
                        (None, "u=-1"), (None, "u=1e300"), (None, "u=gain"), (None, "u=vec"), (None, "u=nope"),
                        (None, "t=1e-300"), (None, "x=0"), (None, "u=1,u=2"), ("u=u,u=x", None)]:  # fmt: skip
        argv = ["identify", "--quiet", path]
        if cols is not None:
            argv += ["--columns", cols]
        if scale is not None:
            argv += ["--scale", scale]
        out = d.out()
        check("recording mapping (identify)", argv + ["--out", out], out, nonsense=True)
        shutil.rmtree(out, ignore_errors=True)


# -- options of the tools --------------------------------------------------------------

def tool_options(d: Dirs, g: dict):
    path = _write(d.file("rec.npz"), g)
    opts = {
        "identify": [["--cutoff-hz", v] for v in ("0", "-1", "nan", "inf", "1e9", "5000")]
        + [["--decimate", v] for v in ("0", "-3", "1e9", "nan", "100000")]
        + [["--trim", v] for v in ("-1,0", "100000,100000", "nan,1", "1", "1,2,3")]
        + [["--butter-order", v] for v in ("0", "-2", "100", "nan")]
        + [["--force-lag", v] for v in ("-1", "nan", "inf", "1e9", "10")]
        + [["--terms", v] for v in ("", "Q", "J,J", "J", "h0")] + [["--off", v] for v in ("J", "J,B,Fc,K,h0", "Z")],
        "diagnose": [["--test-fraction", v] for v in ("0", "1", "-0.5", "nan", "0.9999", "1e-9")]
        + [["--blocks", v] for v in ("0", "1", "-1", "100000", "nan")]
        + [["--alpha", v] for v in ("0", "1", "-1", "nan", "2")]
        + [["--horizon", v] for v in ("0", "-1", "nan", "inf", "1e-12")]
        + [["--decimate", v] for v in ("0", "-1", "1e9", "nan", "fast")]
        + [["--cutoff-hz", v] for v in ("0", "nan", "1e9")] + [["--baseline", v] for v in ("", "Q", "J,J")],
        "frf": [["--nperseg", v] for v in ("0", "1", "-8", "1000000000", "nan")]
        + [["--overlap", v] for v in ("1", "-0.5", "nan", "0.999999")]
        + [["--window", v] for v in ("nope", "kaiser", "('kaiser', 1e300)", "")]
        + [["--f-min", "100", "--f-max", "10"], ["--f-max", "1e9"], ["--f-max", "nan"], ["--closed-loop"]],
        "hysteresis": [["--deadband", v] for v in ("-1", "nan", "inf", "1e9")] + [["--fix-alpha", v] for v in ("-1", "nan", "0", "1e300")],
    }
    for tool, cases in opts.items():
        base = {"identify": ["identify", "--quiet"], "diagnose": ["diagnose", "--no-plots", "--quiet", "--blocks", "4"],
                "frf": ["frf", "--quiet"], "hysteresis": ["hysteresis", "--quiet"]}[tool]  # fmt: skip
        for extra in cases:
            if tool == "diagnose" and extra[0] == "--blocks":
                base = ["diagnose", "--no-plots", "--quiet"]
            out = d.out()
            check(f"options ({tool})", base + [path] + extra + ["--out", out], out)
            shutil.rmtree(out, ignore_errors=True)
    sim = {
        "identify --simulate": [["--amplitude", v] for v in ("0", "-1", "nan", "1e9")] + [["--hz", v] for v in ("0", "-5", "1e9", "nan")]
        + [["--duration", v] for v in ("0", "-1", "1e-9", "nan", "1e9")] + [["--holding-hz", v] for v in ("0", "-1", "1e9")],
        "hysteresis --simulate": [["--amplitude", v] for v in ("0", "nan", "1e9")] + [["--hz", v] for v in ("0", "1e9")]
        + [["--duration", v] for v in ("0", "1e9", "nan")] + [["--large-amplitude", v] for v in ("0", "1e9", "-1")]
        + [["--large-hz", v] for v in ("0", "1e9", "nan")],
        "bode": [["--levels", v] for v in ("0", "-1", "nan", "1e9", ",", "a")] + [["--f-min", "0"], ["--f-min", "100", "--f-max", "10"],
                                                                               ["--f-max", "1e9"], ["--n-freq", "0"], ["--n-freq", "-1"],
                                                                               ["--periods", "0"], ["--periods", "1e9"], ["--periods", "nan"]],
        "loop": [["--levels", v] for v in ("0", "nan", "1e9")] + [["--f-min", "0"], ["--f-min", "100", "--f-max", "10"], ["--f-max", "1e9"],
                                                                  ["--n-freq", "0"], ["--periods", "0"], ["--settle", "-1"], ["--settle", "1e9"],
                                                                  ["--target-error", "-1"], ["--target-error", "nan"], ["--target-error", "1e-9"]],
    }
    for tool, cases in sim.items():
        base = tool.split() + ["--quiet"]
        if tool == "bode":
            base += ["--no-second-drive", "--n-freq", "3"]
        if tool == "loop":
            base += ["--n-freq", "3"]
        for extra in cases:
            out = d.out()
            check(f"options ({tool})", base + extra + ["--out", out], out)
            shutil.rmtree(out, ignore_errors=True)


# -- compensate: model files -----------------------------------------------------------

def models(d: Dirs, g: dict):
    """Model files for ``servo compensate``: a diagnose report.json, an identify
    summary.json and a TOML config, with absurd values and malformed structures."""
    rec = _write(d.file("rec.npz"), g)
    out = d.out()
    rc, _, err = run_cli(["diagnose", rec, "--no-plots", "--quiet", "--blocks", "4", "--out", out])
    report = json.loads((out / "report.json").read_text()) if rc == 0 else None
    idout = d.out()
    rc, _, err2 = run_cli(["identify", rec, "--quiet", "--out", idout])
    summary = json.loads((idout / "summary.json").read_text()) if rc == 0 else None
    if report is None or summary is None:
        FINDINGS.append(f"models: could not make the base files: {err} {err2}")
        return
    TRIED["compensate model", "base files made"] += 2

    def variants(doc, where):
        """Paths of numbers in ``doc`` (dicts and lists), to corrupt one at a time."""
        paths = []

        def walk(v, p):
            if isinstance(v, bool):
                return
            if isinstance(v, (int, float)):
                paths.append(p)
            elif isinstance(v, dict):
                for k, x in v.items():
                    walk(x, p + [k])
            elif isinstance(v, list) and len(v) <= 8:
                for i, x in enumerate(v):
                    walk(x, p + [i])

        walk(doc, [])
        return paths

    def setp(doc, p, val):
        doc = json.loads(json.dumps(doc))
        o = doc
        for k in p[:-1]:
            o = o[k]
        o[p[-1]] = val
        return doc

    for name, doc in (("report.json", report), ("summary.json", summary)):
        paths = variants(doc, name)
        for p in paths[:60]:
            for val in (1e11, -1e11, float("nan"), "x", None, [1]):
                f = d.file(name)
                f.write_text(json.dumps(setp(doc, p, val)))
                o = d.out()
                check(f"compensate model ({name})", ["compensate", f, "--quiet", "--out", o], o,
                      judge=lambda so, out: "")
                shutil.rmtree(o, ignore_errors=True)
        for junk in ("[]", "{}", "null", "1", '"text"', "{", json.dumps({"model": []}), json.dumps({"terms": {}}), ""):
            f = d.file(name)
            f.write_text(junk)
            o = d.out()
            check(f"compensate model ({name})", ["compensate", f, "--quiet", "--out", o], o)
    for toml in ("[drive]\nK = 1e11\n", "[drive]\nJ = -1\n", "[compensator]\nFc = nan\n", "drive = 3\n", "[[drive]]\n",
                 "\x00\x01", "[drive]\nh0 = 1e11\nB = 1e11\n", "[drive]\nFc = 1e11\n", "[drive]\nsigma = 1e11\nHa = 1e11\n"):  # fmt: skip
        f = d.file("model.toml")
        f.write_text(toml)
        o = d.out()
        check("compensate model (toml)", ["compensate", f, "--quiet", "--out", o], o)
        shutil.rmtree(o, ignore_errors=True)
    for extra in (["--force-constant", "0"], ["--force-constant", "-1"], ["--force-constant", "nan"], ["--force-constant", "1e300"],
                  ["--authority", "0"], ["--authority", "-1"], ["--authority", "nan"], ["--authority", "1e300"],
                  ["--recording", rec], ["--recording", "/no/such.csv"], ["--recording", out / "report.json"]):  # fmt: skip
        o = d.out()
        check("compensate options", ["compensate", out / "report.json", "--quiet", "--out", o] + extra, o)
        shutil.rmtree(o, ignore_errors=True)


# -- --out -----------------------------------------------------------------------------

def outs(d: Dirs, g: dict):
    """``--out`` naming an input, an existing file, a non-empty folder, a read-only
    folder, a path under a file, the root."""
    rec = _write(d.file("rec.csv"), g)
    cfg = d.file("cfg.toml")
    cfg.write_text("[run]\nduration_s = 0.05\n")
    model_dir = d.out()
    run_cli(["diagnose", rec, "--no-plots", "--quiet", "--blocks", "4", "--out", model_dir])
    report = model_dir / "report.json"
    existing = d.file("existing.txt")
    existing.write_text("keep me")
    nonempty = d.file("x") .parent
    (nonempty / "keep.txt").write_text("keep me")
    ro = d.root / "readonly"
    ro.mkdir(exist_ok=True)
    os.chmod(ro, 0o555)
    commands = {
        "run": ["run", "--duration", "0.05", "--fast", "--quiet", "--config", cfg],
        "identify": ["identify", "--quiet", rec],
        "diagnose": ["diagnose", "--no-plots", "--quiet", "--blocks", "4", rec],
        "frf": ["frf", "--quiet", rec],
        "hysteresis": ["hysteresis", "--quiet", rec],
        "compensate": ["compensate", "--quiet", report],
        "loop": ["loop", "--quiet", "--n-freq", "2"],
        "bode": ["bode", "--quiet", "--n-freq", "2", "--no-second-drive"],
        "fleet synthetic": ["fleet", "synthetic", "--drives", "2", "--duration", "0.1", "--quiet"],
    }
    for name, argv in commands.items():
        inputs = [a for a in argv if isinstance(a, Path)]
        targets = {"an input": inputs[0] if inputs else cfg, "an existing file": existing, "a non-empty folder": nonempty,
                   "a read-only folder's child": ro / "o", "under a file": existing / "o", "a folder holding the input": rec.parent}  # fmt: skip
        for what, target in targets.items():
            before = {p: p.read_bytes() for p in (rec, cfg, report, existing, nonempty / "keep.txt") if p.exists()}
            outcome = check(f"--out ({what})", argv + ["--out", target], None)
            after = {p: p.read_bytes() for p in before if p.exists()}
            if after != before:
                TRIED[f"--out ({what})", "BUG: an input changed"] += 1
                FINDINGS.append(f"--out {what}: {name} changed or removed an input")
            if outcome == "result" and what != "a read-only folder's child":
                FINDINGS.append(f"--out {what}: {name} exited 0 (read it)")
            if (ro / "o").exists():
                shutil.rmtree(ro / "o", ignore_errors=True)
    os.chmod(ro, 0o755)


def run_steps(steps: dict, only: str) -> None:
    """Run the named ``steps`` (comma-separated ``only``) in order, printing after each
    the tally of what was tried, by kind and outcome, and the findings since the last."""
    for name in only.split(","):
        steps[name]()
        print(f"-- after {name}:", file=sys.__stdout__, flush=True)
        for (kind, outcome), n in sorted(TRIED.items()):
            print(f"  {kind:40s} {outcome:40s} {n}", file=sys.__stdout__)
        for f in FINDINGS:
            print(f, file=sys.__stdout__)
        FINDINGS.clear()
        sys.__stdout__.flush()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", type=Path)
    ap.add_argument("--only", default="configs,cross,recordings,options,models,outs")
    ap.add_argument("--quick", action="store_true", help="run 60 of the accepted config values, not all")
    a = ap.parse_args(argv)
    a.root.mkdir(parents=True, exist_ok=True)
    d = Dirs(a.root)
    g = _good()
    steps = {"configs": lambda: configs(d, a.quick), "cross": lambda: cross_fields(d), "recordings": lambda: recordings(d, g),
             "options": lambda: tool_options(d, g), "models": lambda: models(d, g), "outs": lambda: outs(d, g)}  # fmt: skip
    run_steps(steps, a.only)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Hostile inputs of issue 28, one regression test each: corrupt journals, memory set by
a value or by a file's content, nonsense a run used to accept, errors that left an
output folder behind.  The property-based counterpart is tests/test_hostile.py."""
import json
import os
import resource
import signal
import subprocess
import sys

import numpy as np
import pytest

from servo.cli import main
from servo.io import runlog

MAX_HEADER_BYTES = getattr(runlog, "MAX_HEADER_BYTES", 1 << 20)  # (the old code had no bound: its test runs too)


def _journal(path, header, rows=3, width=None):
    head = header if isinstance(header, bytes) else (json.dumps(header) + "\n").encode()
    width = width or (len(header["columns"]) if isinstance(header, dict) and isinstance(header.get("columns"), list) else 2)
    path.write_bytes(head + np.arange(rows * max(width, 1), dtype="<f8").tobytes())
    return path


def _one_line_error(capsys, rc, code=2):
    err = capsys.readouterr().err
    assert rc == code, err
    assert err.startswith("servo: error: ") and err.count("\n") == 1, err
    return err


GOOD = {"columns": ["t", "x"], "units": {"t": "s"}, "meta": {}}
CORRUPT = {
    "a JSON list": [["t", "x"]],
    "no columns": {"columns": [], "meta": {}},
    "columns not a list": {"columns": "t,x", "meta": {}},
    "a slash in a name": {"columns": ["t", "a/b"], "meta": {}},
    "a non-ASCII name": {"columns": ["t", "\u00e9"], "meta": {}},
    "an empty name": {"columns": ["t", ""], "meta": {}},
    "a number as a name": {"columns": ["t", 3], "meta": {}},
    "units a list": {"columns": ["t", "x"], "units": ["s", "m"], "meta": {}},
    "a unit with a comma": {"columns": ["t", "x"], "units": {"t": "s,m"}, "meta": {}},
    "meta a list": {"columns": ["t", "x"], "meta": [1]},
    "duplicate names": {"columns": ["t", "t"], "meta": {}},
    "not JSON": b"\x00\xffjunk\n",
    "deep nesting": b"[" * 100_000 + b"\n",
    "no newline": b"x" * 10_000,
}


@pytest.mark.parametrize("case", list(CORRUPT))
def test_recover_refuses_a_corrupt_journal_in_one_line_and_writes_nothing(tmp_path, capsys, case):
    """Issue 28: 9 of 20 corrupt journals crashed `servo recover` (exit 70); duplicate
    column names gave a broken NPZ with exit 0."""
    path = _journal(tmp_path / "log.journal", CORRUPT[case])
    rc = main(["recover", str(path)])
    err = _one_line_error(capsys, rc)
    assert "not a run-log journal" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.journal"]  # nothing half-written, the journal kept


def test_recover_still_finalises_a_good_journal(tmp_path, capsys):
    path = _journal(tmp_path / "log.journal", GOOD, rows=5)
    assert main(["recover", str(path)]) == 0
    with np.load(tmp_path / "log.npz") as z:
        np.testing.assert_array_equal(z["x"], np.arange(1, 10, 2.0))
    assert (tmp_path / "log.csv").read_text().splitlines()[0] == "t [s],x"


def test_recover_reads_a_bounded_header_of_a_junk_journal(tmp_path, capsys):
    """Issue 28: a 1 GB junk journal took 2 GB in `servo recover` (its first "line" read
    whole).  A junk file 8x the header bound is refused after reading the bound."""
    path = tmp_path / "junk.journal"
    with open(path, "wb") as fh:
        fh.write(b"y" * (8 * MAX_HEADER_BYTES))
    rc = main(["recover", str(path)])
    err = _one_line_error(capsys, rc)
    assert f"within its first {MAX_HEADER_BYTES} bytes" in err


def test_recover_refuses_a_file_not_named_journal(tmp_path, capsys):
    """Its outputs are named after it: `recover log.npz` would write over its input."""
    path = _journal(tmp_path / "log.npz", GOOD)
    before = path.read_bytes()
    rc = main(["recover", str(path)])
    _one_line_error(capsys, rc)
    assert path.read_bytes() == before


# -- nonsense a run accepted, refused where the config is validated --------------------

from servo.config import Config, from_dict, to_dict  # noqa: E402
from servo.errors import ConfigError  # noqa: E402


def _cfg(**sections):
    data = to_dict(Config())
    for name, values in sections.items():
        data[name].update(values)
    return from_dict(data)


NONSENSE = {
    "a quantum beyond the stroke": (dict(drive=dict(position_quantum=1.0)), "drive.position_quantum"),
    "a quantum equal to the stroke": (dict(drive=dict(position_quantum=15e-3)), "drive.position_quantum"),
    "a disturbance at Nyquist": (dict(scenario=dict(disturbance_hz=25000.0)), "scenario.disturbance_hz"),
    "a disturbance above Nyquist": (dict(scenario=dict(disturbance_hz=40000.0)), "scenario.disturbance_hz"),
    "a prbs above Nyquist": (dict(scenario=dict(excitation="prbs", excitation_f_max=30000.0)), "excitation_f_max"),
    "a chirp from above Nyquist": (dict(scenario=dict(excitation="chirp", excitation_f_min=26000.0)), "excitation_f_min"),
    "a multisine band upside down": (dict(scenario=dict(excitation="multisine", excitation_f_min=3000.0,
                                                        excitation_f_max=2000.0)), "excitation_f_min"),  # fmt: skip
    "a prbs bit longer than its period": (dict(scenario=dict(excitation="prbs", excitation_f_max=2e-4)), "excitation_f_max"),
    "a natural frequency of 5 GHz": (dict(drive=dict(J=1e-9, K=1e12)), "natural frequency"),
    "a pre-sliding stiffness beyond Nyquist": (dict(drive=dict(J=1e-9)), "natural frequency"),
}


@pytest.mark.parametrize("case", list(NONSENSE))
def test_the_config_refuses_values_that_make_a_result_meaningless(case):
    """Issue 28: a quantum beyond the stroke reported "hold 0.0 nm", a disturbance at
    Nyquist vanished, PRBS above Nyquist ran, J = 1e-9 with K = 1e12 reported a 1.69 m
    error on a 15 mm stroke, f_max = 2e-4 Hz for a PRBS took 5.4 GB; all with exit 0."""
    sections, named = NONSENSE[case]
    with pytest.raises(ConfigError, match=named.replace(".", r"\.")):
        _cfg(**sections)


def test_the_physics_checks_leave_sensible_configs_alone():
    _cfg(drive=dict(position_quantum=1e-6, J=1e-6), scenario=dict(disturbance_hz=24000.0))
    _cfg(scenario=dict(excitation="prbs", excitation_f_max=4.4, excitation_period=0.1))
    _cfg(scenario=dict(kind="hdd_benchmark", disturbance_hz=1e5, excitation="prbs", excitation_f_max=1e5))  # unused there


RUN_REFUSED = {
    "hdd at a rate it does not divide": ["--set", "scenario.kind=hdd_benchmark"],
    "a multisine with no line in its band": ["--set", "scenario.excitation=multisine", "--set", "scenario.excitation_f_min=11",
                                             "--set", "scenario.excitation_f_max=12"],  # fmt: skip
    "a holding current beyond the limit": ["--set", "drive.initial_position=0.014", "--set", "drive.K=100"],
    "a chirp above Nyquist": ["--set", "scenario.excitation=chirp", "--set", "scenario.excitation_f_max=30000"],
    "an excitation period too long": ["--set", "scenario.excitation=multisine", "--set", "scenario.excitation_period=9.9",
                                      "--set", "run.sample_rate_hz=200000"],  # fmt: skip
}


@pytest.mark.parametrize("case", list(RUN_REFUSED))
def test_a_refused_run_leaves_no_folder(tmp_path, capsys, case):
    """Issue 28: errors found after the output folder was made left OUT.incomplete/ with
    only config.toml ("recorded data kept"), and the next run with that --out was refused."""
    out = tmp_path / "o"
    rc = main(["run", "--quiet", "--duration", "0.02", "--compensation", "on", "--out", str(out), *RUN_REFUSED[case]])
    err = _one_line_error(capsys, rc)
    assert "kept" not in err and err.startswith("servo: error: config: ")
    assert list(tmp_path.iterdir()) == []


# -- memory set by a file's content, checked before it is allocated --------------------

import zipfile  # noqa: E402

from servo.io import tables  # noqa: E402

MAX_SAMPLES = getattr(tables, "MAX_SAMPLES", 1 << 25)
#: Peak resident memory (MB) a load of these small recordings may take: the imports
#: (numpy, scipy, h5py) and the three used columns; each file below would take more
#: than twice this if its unused or bogus part were read.
PEAK_MB = 200
BIG = 1 << 25  # values in the unused column: 268 MB as float64


def _peak_mb_loading(path, columns=None):
    """Load ``path`` in a fresh interpreter: (peak resident MB, the error line or "")."""
    code = ("from servo.io.recording import load_recording\nfrom servo.errors import ServoError\n"
            f"try:\n    load_recording({str(path)!r}, {columns!r}); err = ''\n"
            "except ServoError as exc:\n    err = str(exc)\n"
            "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM:')][0].split()[1]\n"
            "print(int(hwm) / 1024); print(err)")  # fmt: skip  (VmHWM: this program's peak; ru_maxrss is pytest's after a fork)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=os.getcwd(),
                       env={**os.environ, "PYTHONPATH": os.getcwd()})  # fmt: skip
    assert r.returncode == 0, r.stderr
    peak, err = r.stdout.split("\n", 1)
    return float(peak), err.strip()


def _small_columns(n=200):
    t = np.arange(n) * 1e-3
    return {"t": t, "u": np.sin(t), "x": np.cos(t)}


def _npz_with_zeros(path, columns, name, n):
    """An NPZ of ``columns`` plus a compressed column ``name`` of ``n`` zeros, written in
    blocks (the file is a few hundred kB)."""
    np.savez_compressed(path, **columns)
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf, zf.open(f"{name}.npy", "w", force_zip64=True) as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (n,)})
        block = bytes(1 << 22)
        for _ in range(n * 8 // len(block)):
            f.write(block)
    return path


def test_an_unused_column_of_an_npz_is_never_read(tmp_path):
    """Issue 28: a 3.8 MB NPZ with an unused 3 GB column took 3.2 GB."""
    path = _npz_with_zeros(tmp_path / "r.npz", _small_columns(), "camera", BIG)
    assert path.stat().st_size < 5e6
    peak, err = _peak_mb_loading(path)
    assert err == "" and peak < PEAK_MB, (peak, err)


def test_an_unused_dataset_of_an_hdf5_file_is_never_read(tmp_path):
    """Issue 28: a 1.2 MB HDF5 file with an unused 3 GB column took 3.2 GB."""
    import h5py

    path = tmp_path / "r.h5"
    with h5py.File(path, "w") as f:
        for k, v in _small_columns().items():
            f[k] = v
        f.create_dataset("scope/raw", shape=(BIG,), dtype="f8", chunks=(1 << 16,), compression="gzip")  # all fill value
    assert path.stat().st_size < 5e6
    peak, err = _peak_mb_loading(path)
    assert err == "" and peak < PEAK_MB, (peak, err)


def test_a_used_column_larger_than_the_budget_is_refused_from_its_declared_shape(tmp_path, capsys):
    """A column declaring more than MAX_SAMPLES values: one line naming it and the limit,
    before its data are read (this file holds none of them)."""
    path = tmp_path / "r.npz"
    np.savez(path, **_small_columns())
    with zipfile.ZipFile(path, "a") as zf, zf.open("v.npy", "w") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (10**10,)})
    peak, err = _peak_mb_loading(path)
    assert f"column 'v' holds {10**10} values" in err and str(MAX_SAMPLES) in err, err


def test_a_text_recording_with_no_newline_is_refused_after_one_bounded_line(tmp_path):
    """Issue 28: a 2 GB CSV with no newline took 4.2 GB (its first "line" read whole)."""
    path = tmp_path / "r.csv"
    with open(path, "w") as fh:
        chunk = "1," * (1 << 20)
        for _ in range(128):  # 268 MB of "1,1,1,..." and no newline
            fh.write(chunk)
    peak, err = _peak_mb_loading(path)
    assert "line 1: longer than" in err and peak < PEAK_MB, (peak, err)


def test_a_header_only_csv_is_one_line_that_says_so(tmp_path):
    """Issue 28: a header-only CSV printed a two-line numpy warning, then "column 't' is
    not numeric"."""
    import warnings

    from servo.errors import RecordingError
    from servo.io.recording import load_recording

    path = tmp_path / "r.csv"
    path.write_text("# exported\nt,u,x\n\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning would be printed before the error line
        with pytest.raises(RecordingError, match="a header row .t, u, x. and no rows of numbers"):
            load_recording(path)


# -- a full disk: the error line names the path -----------------------------------------


def _file_size_limit(limit):
    def preexec():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG, as ENOSPC on a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


def test_a_write_that_fails_names_its_file(tmp_path):
    """Issue 28: on a full disk identify, diagnose and recover printed "No space left on
    device" without the path.  Their files are written through atomic_write."""
    import errno

    from servo.cli import os_error_line
    from servo.io.atomic import atomic_write

    def full(tmp):
        open(tmp, "wb").close()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # what a write to a full disk raises: no file name

    with pytest.raises(OSError) as got:
        atomic_write(tmp_path / "report.json", full)
    assert os_error_line(got.value) == f"{tmp_path / 'report.json'}: No space left on device"
    assert list(tmp_path.iterdir()) == []


def test_recover_on_a_full_disk_names_the_file_and_keeps_the_journal(tmp_path):
    path = _journal(tmp_path / "log.journal", GOOD, rows=5000)
    r = subprocess.run([sys.executable, "-m", "servo", "recover", str(path)], capture_output=True, text=True,
                       preexec_fn=_file_size_limit(20_000), env={**os.environ, "PYTHONPATH": os.getcwd()})  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith(f"servo: error: {tmp_path / 'log'}.") and "File too large" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.journal"]


def test_a_kernel_cache_that_cannot_be_written_does_not_fail_the_command(tmp_path):
    """A full disk also fails Numba's cache write while a command compiles its kernels
    (the first run after an install): `servo diagnose` printed "File too large" alone."""
    (tmp_path / "kmod.py").write_text("from numba import float64\nfrom kernels._cache import kernel\n\n\n"
                                      "@kernel(float64(float64))\ndef twice(x):\n    return 2.0 * x\n")  # fmt: skip
    env = {**os.environ, "PYTHONPATH": f"{os.getcwd()}{os.pathsep}{tmp_path}"}  # the package's kernels: from the cache
    r = subprocess.run([sys.executable, "-c", "import kmod; print(kmod.twice(2.0))"], capture_output=True, text=True,
                       preexec_fn=_file_size_limit(100), env=env)  # fmt: skip
    assert r.returncode == 0 and r.stdout == "4.0\n", r.stderr[-500:]


def test_a_small_text_recording_takes_little_memory(tmp_path):
    """Found by tests/test_hostile.py in the first bound on text rows (numpy.loadtxt's
    max_rows allocates that many rows up front: 805 MB for a 10-row CSV)."""
    import tracemalloc

    from servo.io.recording import load_recording

    path = tmp_path / "r.csv"
    t = np.arange(50) * 1e-3
    np.savetxt(path, np.column_stack([t, np.sin(t), np.cos(t)]), delimiter=",", header="t,u,x", comments="")
    tracemalloc.start()
    load_recording(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 4e6, peak


def test_a_text_recording_beyond_its_budget_is_refused_before_a_value_is_parsed(tmp_path, monkeypatch):
    """A text recording was parsed until its values reached the budget, then refused:
    a 2 GB CSV took memory in proportion to the budget (1.07 GB) before its one line.
    Its lines are now counted first, in the memory of one chunk; the error names the
    count and the limit.  (The budget is lowered here to keep the file small.)"""
    import tracemalloc

    from servo.errors import RecordingError
    from servo.io import tables

    monkeypatch.setattr(tables, "MAX_TEXT_VALUES", 3_000_000)  # 1 000 000 rows of 3: 24 MB parsed
    path = tmp_path / "r.csv"
    path.write_text("t,u,x\n" + "0.00125,0.5,-0.25\n" * 1_100_000)  # 20 MB of text, 1.1 M rows
    tracemalloc.start()
    try:
        with pytest.raises(RecordingError) as got:
            tables.read_table(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    msg = str(got.value)
    assert "lines after its header" in msg and "1000000 rows of 3 columns" in msg and "3000000 values" in msg, msg
    assert "\n" not in msg and peak < 6e6, (peak, msg)  # the parse it replaced peaked at ~28 MB


@pytest.mark.parametrize("last", [True, False], ids=["last-newline", "no-last-newline"])
@pytest.mark.parametrize("ending", ["\n", "\r\n"], ids=["LF", "CRLF"])
def test_a_text_recording_at_its_row_budget_loads_and_one_row_more_is_refused(tmp_path, monkeypatch, ending, last):
    """The line count bounds the rows exactly: with room for 10 rows of 3 columns, 10
    rows load (with or without a last newline, behind comments) and 11 are refused."""
    from servo.errors import RecordingError
    from servo.io import tables

    monkeypatch.setattr(tables, "MAX_TEXT_VALUES", 30)
    rows = lambda n: ending.join(f"{i * 1e-3},{i},{-i}" for i in range(n)) + (ending if last else "")  # noqa: E731
    (tmp_path / "ok.csv").write_text(f"# bench 3{ending}t,u,x{ending}" + rows(10))
    assert len(tables.read_table(tmp_path / "ok.csv")["t"]) == 10
    (tmp_path / "over.csv").write_text(f"t,u,x{ending}" + rows(11))
    with pytest.raises(RecordingError, match="at least 11 lines after its header, more than the 10 rows"):
        tables.read_table(tmp_path / "over.csv")


def test_the_hdd_benchmark_scenario_refuses_a_run_beyond_its_budget_before_allocating():
    """Its disturbances are arrays as long as the run: an hour at 52.8 kHz asked for
    ~9 GB.  One tick over the budget is refused before anything is generated."""
    import tracemalloc

    from servo.hdd.benchmark import benchmark
    from servo.run.job import prepare
    from servo.scenarios import hdd_benchmark as scenario

    limit = getattr(scenario, "MAX_BENCHMARK_TICKS", 1 << 24)
    fs = 2.0 / benchmark(2).Ts
    cfg = _cfg(run=dict(sample_rate_hz=fs, duration_s=(limit + 1) / fs), scenario=dict(kind="hdd_benchmark"),
               drive=dict(mode_hz=[], mode_zeta=[], mode_gain=[]))  # fmt: skip
    tracemalloc.start()
    try:
        with pytest.raises(ConfigError, match=f"more than {limit}"):
            prepare(cfg)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak < 50e6, peak


def test_an_unused_compressed_matlab_variable_is_never_inflated(tmp_path):
    """A MATLAB file's compressed variable was inflated whole, used or not (a 130 kB file
    holding 128 MB of zeros took 320 MB), before scipy read any of it."""
    from scipy.io import savemat

    path = tmp_path / "r.mat"
    savemat(path, {**_small_columns(), "camera": np.zeros(BIG // 2)}, do_compression=True)
    assert path.stat().st_size < 1e6
    peak, err = _peak_mb_loading(path)
    assert err == "" and peak < PEAK_MB - 64, (peak, err)  # (the unused variable alone is 134 MB)


def test_a_run_folder_log_is_read_within_the_budget(tmp_path):
    """servo.load_run read every array of a log NPZ, whatever its size."""
    from servo.errors import RecordingError
    from servo.io.runfolder import load_run

    folder = tmp_path / "r"
    folder.mkdir()
    np.savez(folder / "log_compensated.npz", **_small_columns())
    with zipfile.ZipFile(folder / "log_compensated.npz", "a") as zf, zf.open("x2.npy", "w") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (10**10,)})
    with pytest.raises(RecordingError, match=f"not a readable run log .* more than the {MAX_SAMPLES}"):
        load_run(folder)


def test_a_number_of_thousands_of_digits_is_one_line(tmp_path, capsys):
    """Python refuses to read an integer of more than 4300 digits with a ValueError that
    TOML's reader passes on: `servo run` exited 70 (internal error) for it."""
    toml = tmp_path / "c.toml"
    toml.write_text("[run]\nseed = " + "9" * 5000 + "\n")
    for argv in (["--config", str(toml)], ["--set", "run.seed=" + "9" * 5000]):
        rc = main(["run", "--out", str(tmp_path / "o"), *argv])
        _one_line_error(capsys, rc)
    assert list(tmp_path.iterdir()) == [toml]


def test_a_config_error_quotes_a_long_value_in_a_few_characters(capsys, tmp_path):
    rc = main(["run", "--out", str(tmp_path / "o"), "--set", "scenario.excitation=" + "a" * 100_000])
    err = _one_line_error(capsys, rc)
    assert len(err) < 300


def test_a_list_field_holds_at_most_its_budget():
    """2000 reference steps were accepted (each is evaluated on every input window)."""
    with pytest.raises(ConfigError, match="step_times holds 2000 values, more than the 1024"):
        _cfg(scenario=dict(step_times=[0.1] * 2000, step_positions=[0.0] * 2000))


def test_two_roles_cannot_read_one_column(tmp_path):
    """`--columns u=x` identified a drive whose force was its own position (exit 0)."""
    from servo.errors import RecordingError
    from servo.io.recording import load_recording

    path = tmp_path / "r.npz"
    np.savez(path, **_small_columns())
    with pytest.raises(RecordingError, match="u and x would both be column 'x'"):
        load_recording(path, {"u": "x"})


def test_a_diagnosis_horizon_longer_than_the_held_out_part_is_refused(tmp_path, capsys):
    """`servo diagnose --horizon 1e9` asked for 7.28 TiB: MemoryError, exit 70."""
    t = np.arange(4000) * 1e-3
    u = 0.02 * np.sign(np.sin(2 * np.pi * 5 * t))
    path = tmp_path / "r.csv"
    np.savetxt(path, np.column_stack([t, u, np.cumsum(np.cumsum(u)) * 1e-6]), delimiter=",", header="t,u,x", comments="")
    rc = main(["diagnose", str(path), "--horizon", "1e9", "--quiet", "--out", str(tmp_path / "o")])
    err = _one_line_error(capsys, rc)
    assert "not shorter than the held-out part" in err


def test_an_integer_too_large_for_a_float_is_out_of_range():
    """Found by tests/test_hostile.py: from_dict({"run": {"sample_rate_hz": 10**5000}})
    raised OverflowError (math.isfinite converts to float)."""
    with pytest.raises(ConfigError, match="run.sample_rate_hz = an integer of thousands of digits is out of range"):
        from_dict({"run": {"sample_rate_hz": 10**5000}})


@pytest.mark.parametrize("option", [["--n-freq", "100000000"], ["--periods", "1000000000"]])
def test_a_bode_sweep_beyond_its_budget_is_refused_before_it_starts(tmp_path, capsys, option):
    """`servo bode --n-freq 1e8` took over 1 GB and ran on; `--periods 1e9` would simulate
    1e12 samples at its first point."""
    rc = main(["bode", *option, "--quiet", "--out", str(tmp_path / "o")])
    err = _one_line_error(capsys, rc)
    assert "more than the" in err and list(tmp_path.iterdir()) == []


# -- found by the fresh round (docs/robustness.md, "A fresh round") ---------------------


def _run_summary(tmp_path, name, *sets):
    out = tmp_path / name
    argv = ["run", "--duration", "0.05", "--fast", "--compensation", "off", "--log-format", "npz", "--quiet", "--out", str(out)]
    rc = main(argv + [a for s in sets for a in ("--set", s)])
    assert rc == 0
    return json.loads((out / "summary.json").read_text())["runs"]["uncompensated"]


def test_the_plant_quantises_a_position_of_any_ratio_to_its_quantum():
    """drive.position_quantum = 1e-300 m ran with exit 0 and reported "hold 0.0 nm": the
    plant's quantiser floored y/quantum to a 64-bit integer (Numba's math.floor), which
    wraps beyond 2^63, so every measured position was -9e-282 m and the arm never moved.
    The kernel is called here with ratios each side of 2^63."""
    from kernels.plant import plant_measure
    from servo.config import DriveConfig
    from servo.runtime.simplant import build_plant

    p = build_plant(DriveConfig(mode_hz=[], mode_zeta=[], mode_gain=[]), 2e-5)
    p.state["x"] = 3e-7
    for quantum, want in [(1e-9, 3e-7), (1e-26, 3e-7), (1e-300, 3e-7), (0.0, 3e-7), (2e-7, 4e-7)]:
        p.params["quantum"] = quantum
        y, _ = plant_measure(p.state, p.params, p.q, p.gain, 0.0, 0.0)
        assert y == pytest.approx(want, rel=1e-12), (quantum, y)


@pytest.mark.parametrize("quantum", ["1e-300", "5e-324", "1e-20"])
def test_a_quantum_finer_than_a_double_resolves_is_refused(tmp_path, capsys, quantum):
    """Below stroke * 2^-52 a quantum is no quantisation a double can hold: 5e-324 made
    every measured position infinite (exit 3 after a run).  Refused with the limit; 0
    is the way to say none."""
    out = tmp_path / "o"
    rc = main(["run", "--duration", "0.05", "--fast", "--quiet", "--out", str(out), "--set", f"drive.position_quantum={quantum}"])
    err = _one_line_error(capsys, rc)
    # (1e-300 and 5e-324 meet the field's own floor first, SCALE_MIN; 1e-20 the physics check)
    assert ("finer than a double resolves" in err and "write 0" in err) or "below any value a scale" in err, err
    assert not out.exists()
    assert not out.with_name("o.incomplete").exists()


@pytest.mark.parametrize("sets", [["run.fault_position=10"], ["run.fault_position=0.01", "drive.stroke=0.005"]])
def test_a_fault_position_beyond_the_hard_stops_is_refused(tmp_path, capsys, sets):
    """run.fault_position = 10 m on a 15 mm stroke ran with exit 0: the position check
    that stops an unstable run could never fire (the plant's hard stops are at the
    stroke), a safety net silently switched off."""
    out = tmp_path / "o"
    argv = ["run", "--duration", "0.05", "--fast", "--quiet", "--out", str(out)]
    rc = main(argv + [a for s in sets for a in ("--set", s)])
    err = _one_line_error(capsys, rc)
    assert "run.fault_position" in err and "hard stops" in err and not out.exists(), err


def _lab_recording(path, n=4000, dt=1e-4):
    t = np.arange(n) * dt
    u = 0.02 * np.sign(np.sin(2 * np.pi * 25 * t))
    np.savez(path, t=t, u=u, x=np.cumsum(np.cumsum(u)) * dt * dt * 10, gain=np.array(2.0))
    return path


@pytest.mark.parametrize("argv", [["--scale", "t=1e-300"], ["--scale", "t=1e-6"], ["--scale", "t=1e5"],
                                  ["--scale", "u=1,u=2"], ["--columns", "u=u,u=x"], ["--columns", "x=x,x=gain"]])  # fmt: skip
def test_a_time_in_another_unit_or_a_role_given_twice_is_one_line(tmp_path, capsys, argv):
    """`--scale t=1e-300` printed five numpy overflow warnings before its error (a
    sample rate of 1e304 Hz); `--scale t=1e5` (a sample every 10 s) identified a drive;
    `--scale u=1,u=2` ran with the last of the two.  A sample period outside 1 ns..1 s
    and a role given twice are refused where every recording is loaded."""
    path = _lab_recording(tmp_path / "r.npz")
    out = tmp_path / "o"
    rc = main(["identify", str(path), "--quiet", "--out", str(out), *argv])
    err = _one_line_error(capsys, rc)
    assert ("a sample every" in err and "is t in seconds" in err) or "is given twice" in err or (
        "t never exceeds" in err and "below any physical value" in err), err  # (t=1e-300: its magnitude first)
    assert not out.exists() and not out.with_name("o.incomplete").exists()


@pytest.mark.parametrize("argv", [
    ["identify", "--simulate", "--duration", "1e9"], ["identify", "--simulate", "--duration", "inf"],
    ["identify", "--simulate", "--amplitude", "inf"], ["hysteresis", "--simulate", "--duration", "1e9"],
    ["hysteresis", "--simulate", "--duration", "nan"], ["hysteresis", "--simulate", "--large-hz", "nan"],
    ["hysteresis", "--simulate", "--large-hz", "1e-9"]])  # fmt: skip
def test_a_simulated_experiment_beyond_its_budget_or_not_finite_is_one_line(tmp_path, capsys, argv):
    """`identify --simulate --duration 1e9` and `hysteresis --simulate --duration 1e9`
    asked for 364 TiB (MemoryError, exit 70); `--duration nan` and `--large-hz nan` were
    a ValueError (exit 70: min() let the NaN through).  Every in-memory simulation's
    length is checked against MAX_MEMORY_ROWS before its inputs are allocated."""
    out = tmp_path / "o"
    rc = main([*argv, "--quiet", "--out", str(out)])
    err = _one_line_error(capsys, rc)
    assert "finite" in err or "in-memory simulation may hold" in err, err
    assert not out.exists() and not out.with_name("o.incomplete").exists()


def test_an_in_memory_log_beyond_its_budget_is_refused_before_it_is_allocated():
    from servo.errors import ConfigError
    from servo.runtime.closedloop import MAX_MEMORY_ROWS, MemoryLog

    with pytest.raises(ConfigError, match=f"more than the {MAX_MEMORY_ROWS}"):
        MemoryLog(10**13)
    assert MemoryLog(MAX_MEMORY_ROWS // 1024).data.shape[0] == MAX_MEMORY_ROWS // 1024


@pytest.mark.parametrize("extra", [[], ["--nperseg", "64"]])
def test_an_overlap_just_below_one_is_a_valid_response_not_a_division_by_zero(tmp_path, capsys, extra):
    """`servo frf --overlap 0.999999` rounded the overlap to the whole segment: no step
    between segments, ZeroDivisionError, exit 70.  The overlap is at most a segment
    less one sample."""
    path = _lab_recording(tmp_path / "r.npz", n=2048)
    rc = main(["frf", str(path), "--overlap", "0.999999", "--quiet", "--out", str(tmp_path / "o"), *extra])
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "o" / "summary.json").exists()


@pytest.mark.parametrize("argv", [["synthetic", "--drives", "2", "--seed", "-1"],
                                  ["simulate", "--drives", "2", "--seed", "-1", "--vary", "drive.J=normal(1e-3,1e-5)", "--workers", "0",
                                   "--no-plots"],
                                  ["synthetic", "--drives", "2", "--duration", "1e-6"]])  # fmt: skip
def test_a_fleet_seed_or_length_numpy_refuses_is_one_line(tmp_path, capsys, argv):
    """`servo fleet synthetic --seed -1` was numpy's ValueError, exit 70; `--duration
    1e-6` (no sample at 50 kHz) printed three numpy warnings, then an error about
    run.duration_s = 0.0, a value the user never gave."""
    out = tmp_path / "o"
    rc = main(["fleet", *argv, "--quiet", "--out", str(out)])
    err = _one_line_error(capsys, rc)
    assert "--seed -1" in err or "--duration 1e-06" in err, err
    assert not out.exists() and not out.with_name("o.incomplete").exists()


@pytest.mark.parametrize("tool,scale", [("hysteresis", "u=1e-300"), ("identify", "u=1e-300"), ("identify", "x=1e-200"),
                                        ("frf", "x=1e-300")])  # fmt: skip
def test_a_column_below_any_physical_value_is_one_line(tmp_path, capsys, tool, scale):
    """A recording whose u never exceeds 1e-300 A: `servo hysteresis` printed two numpy
    warnings before its error (squares underflow).  Refused where every recording is
    loaded, as values beyond MAGNITUDE_MAX are."""
    path = _lab_recording(tmp_path / "r.npz")
    rc = main([tool, str(path), "--scale", scale, "--quiet", "--out", str(tmp_path / "o")])
    err = _one_line_error(capsys, rc)
    assert "below any physical value" in err, err


@pytest.mark.parametrize("defect", ["u constant", "u and x swapped", "u negated"])
def test_identify_refuses_a_fit_whose_inertia_is_not_positive(tmp_path, capsys, defect):
    """A recording whose force is constant identified "J = -3.34e-19, relative error
    0.0000 %" with exit 0; one with u and x swapped J = -1.2e-8 (robust) and -7.6e-5
    (paper).  No drive has a negative inertia: the fit is refused with the likely causes."""
    from studies.hostile_round import _good, _write

    g = _good(6000)
    cols = {"u constant": {**g, "u": np.full_like(g["u"], 0.01)}, "u and x swapped": {**g, "u": g["x"], "x": g["u"]},
            "u negated": {**g, "u": -g["u"]}}[defect]  # fmt: skip
    path = _write(tmp_path / "r.npz", cols)
    out = tmp_path / "o"
    rc = main(["identify", str(path), "--quiet", "--out", str(out)])
    err = _one_line_error(capsys, rc)
    assert "inertia J = " in err and "is not positive" in err, err
    assert not out.exists() and not out.with_name("o.incomplete").exists()
    assert main(["identify", str(_write(tmp_path / "good.npz", g)), "--quiet", "--out", str(tmp_path / "g")]) == 0


def test_ctrl_c_while_a_compiled_module_initialises_is_an_interruption(tmp_path, capsys, monkeypatch):
    """Ctrl-C 3 s into `servo diagnose` (under load, while scipy's compiled modules were
    still being imported) ended "servo: internal error: ImportError: initialization
    failed", exit 70: pybind11 raises ImportError from the KeyboardInterrupt that cut the
    module's initialisation short.  It is the user's interruption: exit 130, one line."""
    import servo.io.recording as recording

    def cut_short(*a, **k):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as ki:
            raise ImportError("initialization failed") from ki

    monkeypatch.setattr(recording, "load_recording", cut_short)
    rc = main(["identify", str(tmp_path / "r.csv"), "--quiet", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 130 and err == "servo: interrupted\n", (rc, err)
    monkeypatch.setattr(recording, "load_recording", lambda *a, **k: (_ for _ in ()).throw(ImportError("a real bug")))
    rc = main(["identify", str(tmp_path / "r.csv"), "--quiet", "--out", str(tmp_path / "o")])
    assert rc == 70 and "internal error: ImportError: a real bug" in capsys.readouterr().err


@pytest.mark.parametrize("sets", [["controller.kind=track", "controller.track.inertia=5e-324"],
                                  ["controller.kind=track", "controller.track.crossover_hz=5e-324"],
                                  ["controller.kind=track", "controller.track.lowpass_hz=5e-324"],
                                  ["controller.kind=track", "controller.track.inertia=1e-300"],
                                  ["controller.kind=nss", "controller.nss.g=1e-300"],
                                  ["drive.stribeck_velocity=1e-200"], ["drive.mode_hz=[3000.0, 1e-300]"]])  # fmt: skip
def test_a_scale_below_any_physical_value_is_one_line(capsys, sets):
    """The fresh round's config sweep: controller.track.inertia, crossover_hz and
    lowpass_hz of 5e-324 reached the loop design (IndexError, ZeroDivisionError: exit
    70); inertia 1e-300 and nss.g 1e-300 printed numpy warnings before the error.  A
    non-zero value of a field that is a scale (lower bound 0, no upper bound) must be
    at least SCALE_MIN (1e-150: below it its square underflows)."""
    rc = main(["config", *[a for s in sets for a in ("--set", s)]])
    err = _one_line_error(capsys, rc)
    assert "is below any value a scale can compute with" in err, err


def test_a_small_physical_scale_is_still_accepted(capsys):
    rc = main(["config", "--set", "drive.stribeck_velocity=1e-9", "--set", "compensator.sigma=5e-13", "--set", "controller.kind=track",
               "--set", "controller.track.lowpass_hz=0"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err


@pytest.mark.parametrize("value", [10**5000, ["x"] * 100_000], ids=["5000 digits", "a long list"])
def test_a_path_field_given_a_huge_non_string_is_one_config_error(value):
    """Found by the slow hostile suite on scenario.hdd_package, a field added since the
    last round: the error for a non-string path quoted the value with repr, which raises
    ValueError on an integer of thousands of digits (an internal error through the API)
    and quotes a long list whole."""
    from servo.config import from_dict
    from servo.errors import ConfigError

    with pytest.raises(ConfigError, match="scenario.hdd_package must be a string") as got:
        from_dict({"scenario": {"hdd_package": value}})
    assert len(str(got.value)) < 200

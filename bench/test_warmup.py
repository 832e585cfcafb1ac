"""Warm-up: nothing compiles in a loop; the first tick after ``configure``, the cold
start of ``servo run`` and the fixed cost of ``servo diagnose`` are measured and kept low.

Each figure comes from fresh processes (a warm process would hide first-call costs):
``python -m bench.probe`` (imports, a short tick-path run, the Numba cache counters),
``python -m servo run`` itself, whose ``summary.json`` gives its cold start (process
start to first tick) and its first tick, and ``python -m bench.startprobe diagnose``
(``servo diagnose`` stopped once its recording is read).  Medians of 3 processes; the
start-up figures are ratios to ``import numpy, numba`` timed in a fresh interpreter just
before each process, the floor no command that runs compiled kernels goes below.
"""
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bench.budgets import (BUDGETS, DIAGNOSE_FIXED_OVER_IMPORT_FLOOR_MAX, STARTUP_OVER_DEPENDENCIES_MAX,
                           STARTUP_OVER_IMPORT_FLOOR_MAX)

PROCESSES = 3
ROOT = Path(__file__).resolve().parents[1]


def _run(args):
    """A fresh interpreter in the repository root (so ``-m bench.probe`` and ``-m servo``
    resolve to this checkout wherever pytest was started)."""
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600, cwd=ROOT)


@pytest.fixture(scope="module")
def probes():
    out = []
    for _ in range(PROCESSES):
        r = _run(["-m", "bench.probe"])
        assert r.returncode == 0, r.stderr
        out.append(json.loads(r.stdout.strip().splitlines()[-1]))
    return out


def import_floor_s() -> float:
    """``import numpy, numba`` in a fresh interpreter, wall seconds (interpreter start
    included): the floor of every command that runs compiled kernels."""
    t0 = time.perf_counter()
    r = _run(["-c", "import numpy, numba"])
    floor = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    return floor


@pytest.fixture(scope="module")
def servo_runs(tmp_path_factory):
    """Summaries of fresh ``servo run`` processes, each with ``import_floor_s``: the import
    of numpy and numba timed in a fresh interpreter just before it (the floor no command
    that runs compiled kernels can go below)."""
    out = []
    for i in range(PROCESSES):
        floor = import_floor_s()
        d = tmp_path_factory.mktemp(f"run{i}")
        r = _run(["-m", "servo", "run", "--duration", "0.02", "--compensation", "on", "--out", str(d)])
        assert r.returncode == 0, r.stderr
        out.append({**json.loads((d / "summary.json").read_text()), "import_floor_s": floor})
    return out


def test_no_kernel_compiles_after_the_first_import(probes, record):
    """Every kernel loads from the on-disk cache (this session's import wrote it), and no
    dispatcher gains a specialization after import: nothing can compile in a loop."""
    p = probes[-1]
    record.check("kernels load from the cache", dispatchers=p["dispatchers"], compiled=p["compiled_not_cached"],
                 specialised_after_import=p["specialised_after_import"])  # fmt: skip
    assert p["dispatchers"] >= 20
    assert p["compiled_not_cached"] == [], f"compiled instead of loaded from the cache: {p['compiled_not_cached']}"
    assert p["specialised_after_import"] == [], f"compiled after import: {p['specialised_after_import']}"


def test_first_tick_after_configure(cfg, probes, servo_runs, record):
    """The first tick of a fresh process, through the closed loop (probe) and through
    ``servo run``: median within 10 periods (nothing compiles, draws noise or collects
    garbage in it)."""
    probe_us = float(np.median([p["first_tick_us"] for p in probes]))
    run_us = float(np.median([s["runs"]["compensated"]["tick_us_first"] for s in servo_runs]))
    median_tick_us = float(np.median([p["tick_us_median"] for p in probes]))
    record.figure("first_tick", run_us * 1e3, "first_tick", probe_first_tick_us=probe_us, tick_us_median=median_tick_us)
    limit = BUDGETS["first_tick"].ns(cfg) / 1e3
    for what, us in (("servo run", run_us), ("probe", probe_us)):
        assert us <= limit, f"first tick after configure ({what}): {us:.0f} us, over its budget of {limit:.0f} us (10 periods)"


def test_cold_start_of_servo_run(servo_runs, probes, record):
    """Process start to the first tick of ``servo run`` (interpreter, imports, loading the
    cached kernels, configure), against the import of its dependencies measured in the
    same session: at most 3x."""
    deps = []
    for _ in range(PROCESSES):
        t0 = time.perf_counter()
        r = _run(["-c", "import numba, numpy, scipy.linalg, matplotlib.pyplot"])
        deps.append(time.perf_counter() - t0)
        assert r.returncode == 0, r.stderr
    deps_s = float(np.median(deps))
    startup = [s["startup_s"] for s in servo_runs]
    if any(s is None for s in startup):
        pytest.skip("process start time unavailable (no /proc): cold start not measured")
    startup_s = float(np.median(startup))
    import_kernels_s = float(np.median([p["import_kernels_s"] for p in probes]))
    record.figure("cold_start", startup_s * 1e9, dependencies_import_s=deps_s, import_kernels_s=import_kernels_s,
                  import_runjob_s=float(np.median([p["import_runjob_s"] for p in probes])))  # fmt: skip
    record.ratio("cold_start_over_dependencies", startup_s / deps_s, f"<= {STARTUP_OVER_DEPENDENCIES_MAX:g}",
                 startup_s=startup_s, dependencies_s=deps_s)  # fmt: skip
    assert startup_s <= STARTUP_OVER_DEPENDENCIES_MAX * deps_s, (
        f"servo run takes {startup_s:.2f} s from process start to its first tick, more than "
        f"{STARTUP_OVER_DEPENDENCIES_MAX:g}x the {deps_s:.2f} s its dependencies take to import")


def test_cold_start_over_the_import_floor(servo_runs, record):
    """Process start to the first tick of ``servo run`` against ``import numpy, numba``
    timed just before each run: what the command adds to the floor (its own imports, the
    cached kernels, configure).  scipy.signal, matplotlib, dask and pyarrow are imported
    where they are used, not before the first tick (``tests/test_startup_imports.py``)."""
    startup = [s["startup_s"] for s in servo_runs]
    if any(s is None for s in startup):
        pytest.skip("process start time unavailable (no /proc): cold start not measured")
    ratios = [s["startup_s"] / s["import_floor_s"] for s in servo_runs]
    ratio = float(np.median(ratios))
    record.ratio("cold_start_over_import_floor", ratio, f"<= {STARTUP_OVER_IMPORT_FLOOR_MAX:g}",
                 startup_s=float(np.median(startup)),
                 import_floor_s=float(np.median([s["import_floor_s"] for s in servo_runs])))  # fmt: skip
    print(f"\nservo run: {np.median(startup):.2f} s from process start to its first tick, {ratio:.2f}x import numpy, "
          f"numba (per process: {', '.join(f'{r:.2f}' for r in ratios)})")
    assert ratio <= STARTUP_OVER_IMPORT_FLOOR_MAX, (
        f"servo run takes {ratio:.2f}x the import of numpy and numba from process start to its first tick "
        f"(bound {STARTUP_OVER_IMPORT_FLOOR_MAX:g})")


@pytest.fixture(scope="module")
def tiny_recording(tmp_path_factory):
    """A 0.1 s recording (5000 samples at 50 kHz) of the default drive moving: reading it
    is instant, so what ``servo diagnose`` pays before it is its fixed cost."""
    t = np.arange(5000) / 50e3
    x = 1e-3 * np.sin(2 * np.pi * 20 * t)
    u = 1e-3 * (2 * np.pi * 20) ** 2 * np.sin(2 * np.pi * 20 * t) + 1e-3 * np.sign(np.cos(2 * np.pi * 20 * t))
    path = tmp_path_factory.mktemp("tiny") / "tiny.npz"
    np.savez(path, t=t, u=u, x=x)
    return path


def test_diagnose_fixed_cost_over_the_import_floor(tiny_recording, record):
    """Process start to the recording read by ``servo diagnose`` (its imports: numpy,
    numba, the scipy modules the diagnosis uses (signal, stats, optimize), its cached
    kernels; parsing; reading) against ``import numpy, numba`` timed just before each
    process.  Nothing it does not use is imported on the way: no matplotlib before the
    diagnosis (its plots come after), no dask, pyarrow, h5py or python-control."""
    got = []
    for _ in range(PROCESSES):
        floor = import_floor_s()
        r = _run(["-m", "bench.startprobe", "diagnose", str(tiny_recording)])
        assert r.returncode == 0, r.stderr[-3000:]
        probe = json.loads(r.stdout.strip().splitlines()[-1])
        if probe["fixed_s"] is None:
            pytest.skip("process start time unavailable (no /proc): fixed cost not measured")
        got.append({**probe, "import_floor_s": floor})
    assert got[-1]["samples"] == 5000
    unused = [m for m in ("matplotlib", "dask", "pyarrow", "h5py", "control") if got[-1]["modules"][m]]
    assert unused == [], f"servo diagnose imports {unused} before it reads its recording"
    ratio = float(np.median([g["fixed_s"] / g["import_floor_s"] for g in got]))
    fixed_s = float(np.median([g["fixed_s"] for g in got]))
    floor_s = float(np.median([g["import_floor_s"] for g in got]))
    record.ratio("diagnose_fixed_over_import_floor", ratio, f"<= {DIAGNOSE_FIXED_OVER_IMPORT_FLOOR_MAX:g}",
                 fixed_s=fixed_s, import_floor_s=floor_s, per_process=got)  # fmt: skip
    print(f"\nservo diagnose: {fixed_s:.2f} s from process start to its recording read, "
          f"{ratio:.2f}x import numpy, numba ({floor_s:.2f} s)")
    assert ratio <= DIAGNOSE_FIXED_OVER_IMPORT_FLOOR_MAX, (
        f"servo diagnose takes {ratio:.2f}x the import of numpy and numba from process start to its recording read "
        f"(bound {DIAGNOSE_FIXED_OVER_IMPORT_FLOOR_MAX:g})")

"""``servo run`` reaches its first tick without the heavy libraries it does not use there.

scipy.signal (with scipy.stats behind it), matplotlib, dask and pyarrow each take 0.5-2 s
to import; a run of the default scenario needs none of them before its first tick
(its plots import matplotlib after the runs).  A fresh interpreter does what ``servo
run`` does up to the loop: the command line, the run job's module, the configuration,
the scenario's inputs and the simulated drive, then lists what it imported.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("scipy.signal", "scipy.stats", "matplotlib", "dask", "distributed", "pyarrow", "h5py", "servo.hdd")

PROBE = r"""
import json, sys
from servo.cli import build_parser
from servo.cli.common import config_from_args
import servo.run.job, servo.io.outdir, servo.io.progress, servo.io.provenance
from servo.runtime.simdriver import SimDriver
from servo.scenarios import scenario_inputs

cfg = config_from_args(build_parser().parse_args(["run", "--set", sys.argv[1]]))
driver = SimDriver(cfg, scenario_inputs(cfg))
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ("scipy", "matplotlib", "dask", "distributed",
                                                                       "pyarrow", "h5py", "servo"))))
"""


@pytest.mark.parametrize("excitation", ["none", "multisine"])
def test_a_run_starts_without_the_heavy_libraries(excitation):
    r = subprocess.run([sys.executable, "-c", PROBE, f"scenario.excitation={excitation}"], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    loaded = json.loads(r.stdout.strip().splitlines()[-1])
    heavy = [m for m in loaded if any(m == h or m.startswith(h + ".") for h in HEAVY)]
    assert heavy == [], f"imported before the first tick: {heavy}"


def test_the_config_loads_no_kernel_and_no_scipy():
    """The config's sections are built from the physics modules (:mod:`servo.physics`);
    those keep their diagnosis and compensator kernels behind the calls that use them, so
    that reading a config (every command's first step) compiles or loads no kernel and
    imports no scipy."""
    probe = ("import json, sys; import servo.config; "
             "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('kernels', 'scipy'))))")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == ["kernels", "kernels._cache"]


PARSER_PROBE = r"""
import json, sys
from servo.cli import build_parser
build_parser()  # every command's parser: what `servo --help` and every command pay first
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ("numba", "llvmlite", "scipy", "matplotlib", "dask",
                                                                       "distributed", "pyarrow", "h5py", "control"))))
"""


def test_the_command_line_imports_no_numba_and_no_scipy():
    """``servo --help`` (every command's parser, built by every command before it runs)
    imports neither Numba nor scipy nor any other heavy library: each command imports
    what it uses in its handler, so ``servo --help`` answers in a fraction of a second."""
    r = subprocess.run([sys.executable, "-c", PARSER_PROBE], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == []


DIAGNOSE_PROBE = r"""
import json, sys
import servo.cli.diagnose, servo.diagnose.job, servo.io.recording
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ("matplotlib", "dask", "distributed", "pyarrow",
                                                                       "h5py", "control"))))
"""


def test_a_diagnosis_starts_without_plotting_or_dask():
    """What ``servo diagnose`` imports before it reads its recording (its job's modules)
    holds no matplotlib (its plots are drawn after the diagnosis), no Dask, pyarrow, h5py
    (an HDF5 recording imports it when read) or python-control."""
    r = subprocess.run([sys.executable, "-c", DIAGNOSE_PROBE], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == []


def test_a_mat_v5_recording_is_read_without_h5py():
    """A MAT v5 file (EMPS's) is told from a v7.3 one (HDF5) by its signature, read
    without importing h5py (0.1-0.3 s), which only a v7.3 file needs."""
    mat = ROOT.parent / "shared" / "data" / "emps" / "DATA_EMPS.mat"
    probe = ("import json, sys; from servo.io.recording import load_recording; "
             f"rec = load_recording({str(mat)!r}, {{'u': 'vir', 'x': 'qm'}}); "
             "print(json.dumps([len(rec.t), 'h5py' in sys.modules]))")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    n, h5 = json.loads(r.stdout.strip().splitlines()[-1])
    assert n > 1000 and h5 is False

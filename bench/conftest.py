"""Fixtures of the benchmarks, and the results file.

Every benchmark records its figure with the ``record`` fixture; at the end of the session
they are written to ``bench/results/latest.json`` (git-ignored) with the machine, the
versions, the C compiler and flags, and the command.  ``python -m bench.table`` turns that
file into the table of ``bench/README.md``.
"""
from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numba
import numpy as np
import pytest

from bench import cref, workload
from bench.budgets import BUDGETS

RESULTS_DIR = Path(__file__).with_name("results")
_RESULTS: dict = {"figures": {}, "ratios": {}, "checks": {}, "c_reference": None}


def pytest_configure(config):
    """The benchmarks time one process at a time: pytest-benchmark turns itself off under
    pytest-xdist (``-n``/``--dist``), and the ratios would be read beside a second worker."""
    if config.getoption("dist", "no") != "no" or os.environ.get("PYTEST_XDIST_WORKER"):
        raise pytest.UsageError("bench/: the benchmarks run one at a time: leave out -n and --dist")


@pytest.fixture(scope="session")
def cfg():
    """The config the budgets come from (the default: 50 kHz)."""
    return workload.config()


@pytest.fixture(scope="session")
def cref_lib(tmp_path_factory):
    """The C reference, built now with the system C compiler, or a skip saying why."""
    cc = cref.find_compiler()
    if cc is None:
        pytest.skip("no C compiler on this machine ($CC, cc, gcc, clang): the C reference and the Numba/C ratio are skipped")
    lib = cref.CRef.load(tmp_path_factory.mktemp("cref"), cc)
    _RESULTS["c_reference"] = {"compiler": lib.compiler, "version": _compiler_version(lib.compiler), "flags": lib.flags}
    return lib


def _compiler_version(cc: str) -> str:
    import subprocess

    r = subprocess.run([cc, "--version"], capture_output=True, text=True)
    return r.stdout.splitlines()[0] if r.returncode == 0 and r.stdout else "?"


class Recorder:
    """What the benchmarks measured, for ``bench/results/latest.json``."""

    def __init__(self, cfg):
        self.cfg = cfg

    def figure(self, name: str, ns: float, budget: str | None = None, **extra) -> float:
        """A per-sample figure (ns) and, if given, its budget from :data:`BUDGETS`."""
        entry = {"ns": ns, **extra}
        if budget is not None:
            b = BUDGETS[budget]
            entry.update(budget=budget, budget_ns=b.ns(self.cfg), fraction_of_period=b.fraction)
        _RESULTS["figures"][name] = entry
        return ns

    def ratio(self, name: str, value: float, bound: str, **extra) -> float:
        _RESULTS["ratios"][name] = {"ratio": value, "bound": bound, **extra}
        return value

    def check(self, name: str, **values) -> None:
        _RESULTS["checks"][name] = values


@pytest.fixture(scope="session")
def record(cfg):
    return Recorder(cfg)


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def pytest_sessionfinish(session, exitstatus):
    if not (_RESULTS["figures"] or _RESULTS["ratios"] or _RESULTS["checks"]):
        return
    cfg = workload.config()
    out = {
        "when": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "command": "python -m pytest " + " ".join(session.config.invocation_params.args),
        "exit_status": int(exitstatus),
        "machine": {"cpu": _cpu_model(), "cores": os.cpu_count(), "platform": platform.platform()},
        "versions": {"python": sys.version.split()[0], "numba": numba.__version__, "numpy": np.__version__},
        "sample_rate_hz": cfg.run.sample_rate_hz,
        "period_ns": cfg.dt * 1e9,
        **_RESULTS,
    }
    RESULTS_DIR.mkdir(exist_ok=True)
    tmp = RESULTS_DIR / ".latest.json.tmp"
    tmp.write_text(json.dumps(out, indent=2))
    os.replace(tmp, RESULTS_DIR / "latest.json")

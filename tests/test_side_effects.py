"""A library as well as a CLI: importing any module changes no global state (the user's
matplotlib backend above all), plot functions return their Figure and write a file only
when given a path, and only the command line selects Agg."""
from __future__ import annotations

import json
import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import hil
import kernels
import servo

ROOT = Path(__file__).resolve().parents[1]


def all_modules() -> list[str]:
    """Every importable module of the three packages, but ``__main__`` (which runs the CLI)."""
    names = []
    for pkg in (kernels, servo, hil):
        names.append(pkg.__name__)
        for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if not m.name.endswith("__main__"):
                names.append(m.name)
    return names


#: Imports every module in turn in a fresh interpreter whose user chose the "svg"
#: backend, and after each compares what a notebook user would notice.  The
#: dependencies are imported first: what they do on import (numpy, scipy and
#: python-control add warning filters) is theirs, not the package's.
PROBE = r"""
import copy, json, os, signal, sys, warnings, importlib
import matplotlib
matplotlib.use("svg")
import numpy as np
import numba, scipy.signal, scipy.stats, scipy.optimize, scipy.linalg, scipy.io, control, serial, cobs
import matplotlib.figure

def state():
    return {
        "backend": matplotlib.get_backend(),
        "pyplot_imported": "matplotlib.pyplot" in sys.modules,
        "np_err": np.geterr(),
        "np_print": {k: str(v) for k, v in np.get_printoptions().items()},
        "warnings": [repr(f) for f in warnings.filters],
        "signals": {s: repr(signal.getsignal(getattr(signal, s))) for s in ("SIGINT", "SIGTERM")},
        "env": dict(os.environ),
        "rc_changed": sorted(k for k, v in matplotlib.rcParams.items()
                             if k != "backend" and repr(v) != repr(matplotlib.rcParamsDefault[k])),
    }

before = state()
changes = {}
for name in json.loads(sys.argv[1]):
    importlib.import_module(name)
    now = state()
    diff = sorted(k for k in before if now[k] != before[k])
    if diff:
        changes[name] = diff
        before = now
print(json.dumps(changes))
"""


def test_importing_any_module_changes_no_global_state():
    mods = all_modules()
    assert len(mods) > 60 and "servo.run.plots" in mods and "servo.io.plotting" in mods
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    r = subprocess.run([sys.executable, "-c", PROBE, json.dumps(mods)], capture_output=True, text=True, cwd=ROOT,
                       env=env, timeout=300)  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == {}


def test_the_command_line_selects_agg_and_only_it():
    code = ("import os, sys; import servo.cli as c; assert 'matplotlib' not in sys.modules; c.use_agg(); "
            "import matplotlib; print(matplotlib.get_backend().lower()); "
            "matplotlib.use('svg'); c.use_agg(); print(matplotlib.get_backend().lower())")  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["agg", "agg"]  # matplotlib not yet loaded, and already loaded with another backend


def _fake_logs(cfg, n=400):
    from kernels.compose import LOG_COLUMNS

    col = {c: i for i, c in enumerate(LOG_COLUMNS)}
    a = np.zeros((n, len(LOG_COLUMNS)))
    t = np.arange(n) * cfg.dt
    a[:, col["t"]] = t
    a[:, col["r"]] = 1e-6 * (t > t[n // 4])
    a[:, col["x"]] = a[:, col["r"]] * (1 - np.exp(-(t - t[n // 4]).clip(0) / (20 * cfg.dt)))
    a[:, col["e"]] = a[:, col["r"]] - a[:, col["x"]]
    return {"compensated": a, "uncompensated": a.copy()}


def test_plot_functions_return_figures_and_write_only_when_given_a_path(tmp_path, monkeypatch):
    from matplotlib import _pylab_helpers
    from matplotlib.figure import Figure

    from servo.config import load_config
    from servo.run.plots import plot_run

    cfg = load_config()
    logs = _fake_logs(cfg)
    monkeypatch.chdir(tmp_path)
    managers = len(_pylab_helpers.Gcf.get_all_fig_managers())
    figs = plot_run(cfg, logs)
    assert set(figs) == {"tracking.png", "steps.png", "current.png"}
    assert all(isinstance(f, Figure) for f in figs.values())
    assert list(tmp_path.iterdir()) == []  # nothing written without a path
    assert len(_pylab_helpers.Gcf.get_all_fig_managers()) == managers  # not registered with pyplot

    from servo.runtime.durations import Durations

    class R:
        timing = Durations()

    R.timing.add(np.random.default_rng(1).uniform(3e3, 3e4, 500))

    out = tmp_path / "out"
    out.mkdir()
    figs = plot_run(cfg, logs, {"compensated": R()}, out)  # the call servo.run.job makes
    assert sorted(p.name for p in out.iterdir()) == sorted(figs) == ["current.png", "steps.png", "timing.png",
                                                                     "tracking.png"]  # fmt: skip
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in out.iterdir())


@pytest.mark.parametrize("name", ["plot_acceleration", "plot_force_fit"])
def test_identification_plots_return_figures(tmp_path, name):
    from matplotlib.figure import Figure

    import servo.identify.plots as plots
    from servo.identify.identification import identify
    from servo.identify.regressors import RobustSettings
    from servo.io.recording import Recording

    rng = np.random.default_rng(0)
    t = np.arange(4000) * 1e-3
    x = 1e-3 * np.sin(2 * np.pi * 2 * t)
    v = np.gradient(x, t)
    u = 0.5 * np.gradient(v, t) + 3 * v + 0.01 * rng.standard_normal(t.size)
    rec = Recording(t=t, u=u, x=x, v=v, source="synthetic")
    ident = identify(rec, "paper", ["J", "B", "h0"], RobustSettings())
    fig = getattr(plots, name)(ident)
    assert isinstance(fig, Figure) and list(tmp_path.iterdir()) == []
    fig = getattr(plots, name)(ident, tmp_path / "a.png")
    assert isinstance(fig, Figure) and (tmp_path / "a.png").stat().st_size > 5000

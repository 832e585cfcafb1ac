"""Test-wide settings.

Progress lines (:mod:`servo.io.progress`) appear only after a job has run
``DELAY_S`` seconds: on a loaded machine a test that reads a command's stderr (one
``servo: error:`` line) could catch one.  They are off in the tests run in this process,
except where a test turns them on (``tests/test_progress.py``); commands run as
subprocesses that fail mid-job pass ``--quiet``.

The kernels are compiled once before the first test (``servo warmup``), for this process
and for the commands the tests start as subprocesses (from another folder, which may
import an installed copy): a command that compiles says so on stderr, and on a fresh
install the first test to read a command's one error line would read those lines too.
The tests of compilation itself use caches of their own (``SERVO_NUMBA_CACHE``).
"""
import math
import subprocess
import sys

import pytest


@pytest.fixture(scope="session", autouse=True)
def _kernels_compiled(tmp_path_factory):
    from servo.runtime.warmup import compile_all

    compile_all()
    r = subprocess.run([sys.executable, "-m", "servo", "warmup", "--quiet"], cwd=tmp_path_factory.mktemp("warmup"),
                       capture_output=True, text=True, timeout=3600)  # fmt: skip
    assert r.returncode == 0, r.stderr


@pytest.fixture(autouse=True)
def _no_progress_lines(monkeypatch):
    monkeypatch.setattr("servo.io.progress.DELAY_S", math.inf)


#: modules the fast tier runs only in other processes (so never in this one's sys.modules)
OTHER_PROCESS_ONLY = {
    "servo.__main__": "`python -m servo`, which the CLI tests start as subprocesses",
    "servo.fleet.workerlog": "a Dask worker plugin, imported in the workers the fleet tests start",
}


def _package_modules(root) -> set[str]:
    out = set()
    for top in ("servo", "kernels", "hil"):
        for path in (root / top).rglob("*.py"):
            parts = path.relative_to(root).with_suffix("").parts
            out.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return out


def _imported(root) -> set[str]:
    return _package_modules(root) & set(sys.modules)


#: the package modules the pytest-xdist workers imported, joined by the controller
_WORKER_MODULES = pytest.StashKey[set]()


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    """pytest-xdist's controller: a worker's imported modules, sent when it finishes."""
    node.config.stash.setdefault(_WORKER_MODULES, set()).update(node.workeroutput.get("modules", ()))


def pytest_sessionfinish(session, exitstatus):
    """The README's test command (the fast tier over every test file) must import every
    module of the package in its processes (this one, or the pytest-xdist workers, whose
    lists the controller joins), but for :data:`OTHER_PROCESS_ONLY`: a module that only
    the slow tier touches fails the run here, with its name."""
    cfg = session.config
    if hasattr(cfg, "workerinput"):  # an xdist worker: report to the controller, which judges
        cfg.workeroutput["modules"] = sorted(_imported(cfg.rootpath))
        return
    whole = not cfg.option.keyword and [str(a) for a in cfg.args] in ([], ["tests"], [str(cfg.rootpath / "tests")])
    if exitstatus != 0 or not whole or cfg.option.markexpr != "not slow" or cfg.option.collectonly:
        return
    imported = _imported(cfg.rootpath) | cfg.stash.get(_WORKER_MODULES, set())
    missing = sorted(_package_modules(cfg.rootpath) - imported - set(OTHER_PROCESS_ONLY))
    if missing:
        print(f"\nthe fast tier imports no test of: {', '.join(missing)} (tests/conftest.py)", file=sys.stderr)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED

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

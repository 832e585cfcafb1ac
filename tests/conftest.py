"""Test-wide settings.

Progress lines (:mod:`servo.io.progress`) appear only after a job has run
``DELAY_S`` seconds: on a loaded machine a test that reads a command's stderr (one
``servo: error:`` line) could catch one.  They are off in the tests run in this process,
except where a test turns them on (``tests/test_progress.py``); commands run as
subprocesses that fail mid-job pass ``--quiet``.
"""
import math

import pytest


@pytest.fixture(autouse=True)
def _no_progress_lines(monkeypatch):
    monkeypatch.setattr("servo.io.progress.DELAY_S", math.inf)

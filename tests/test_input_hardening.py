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

"""docs/api.md is executed: its ```python blocks run in order in one namespace, from the
repository's root, as a notebook would run them.  A block that fails names itself."""
from __future__ import annotations

import pytest

import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "api.md"


def blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


@pytest.mark.slow
def test_the_api_walkthrough_runs(monkeypatch):
    code = blocks(DOC.read_text())
    assert len(code) >= 6  # recording, identify, plot, diagnose, frf, files
    monkeypatch.chdir(ROOT)
    ns: dict = {"__name__": "api_doc"}
    for i, block in enumerate(code, start=1):
        try:
            exec(compile(block, f"docs/api.md block {i}", "exec"), ns)
        except Exception as exc:  # say which block and line of the doc failed
            raise AssertionError(f"docs/api.md block {i} failed: {type(exc).__name__}: {exc}\n{block}") from exc
    assert os.getcwd() == str(ROOT)

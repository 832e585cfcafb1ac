"""A notebook, for real: a fresh Jupyter kernel (nbclient, ipykernel) draws the figures
servo returns and shows its results' short summaries, and docs/api.md runs cell by cell
as a notebook."""
from __future__ import annotations

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from tests.test_api_doc import blocks

ROOT = Path(__file__).resolve().parents[1]


def run_cells(cells: list[str], timeout: int = 600):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in cells])
    nb.cells.insert(0, nbformat.v4.new_code_cell(f"import sys; sys.path.insert(0, {str(ROOT)!r})"))
    NotebookClient(nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(ROOT)}}).execute()
    return nb.cells[1:]


@pytest.mark.slow
def test_a_fresh_kernel_draws_a_figure_and_shows_short_summaries():
    """Once only ``<Figure size 1000x700 with 2 Axes>``, a 300 kB repr of a diagnosis and
    86 kB of a frequency response."""
    cells = run_cells([
        "import numpy as np, servo\n"
        "rec = servo.load_recording('../shared/data/emps/DATA_EMPS.mat', columns={'u': 'vir', 'x': 'qm', 'r': 'qg'},"
        " scale={'u': 'gtau'})\n"
        "resp = servo.frf(rec, closed_loop=True, force_unit='N')\n"
        "resp",
        "from servo.frf.plots import plot_frf\nplot_frf(resp)",
        "run = servo.simulate(run={'duration_s': 0.1})\nrun",
        "from servo.runtime.controller import Controller\nController(servo.Config())",
    ])  # fmt: skip
    resp_out, fig_out, run_out, ctl_out = (c.outputs[-1] for c in cells)
    assert resp_out["output_type"] == "execute_result"
    text = resp_out["data"]["text/plain"]
    assert text.startswith("<FrequencyResponse") and len(text) < 300
    assert "image/png" in fig_out["data"] and len(fig_out["data"]["image/png"]) > 10_000
    assert "text/html" in run_out["data"] and "tracking error RMS" in run_out["data"]["text/html"]
    assert len(run_out["data"]["text/plain"]) < 300
    assert ctl_out["data"]["text/plain"].startswith("<Controller pi at 50 kHz") and " at 0x" not in ctl_out["data"]["text/plain"]


@pytest.mark.slow
def test_docs_api_md_runs_as_a_notebook():
    code = blocks((ROOT / "docs" / "api.md").read_text())
    cells = run_cells(code)
    for i, c in enumerate(cells, start=1):
        errors = [o for o in c.outputs if o["output_type"] == "error"]
        assert not errors, f"docs/api.md block {i}: {errors}"


def test_import_servo_imports_no_subpackage_and_offers_the_api():
    import subprocess
    import sys

    code = ("import sys, servo; loaded = sorted(m for m in sys.modules if m.startswith(('servo.', 'numba', 'numpy')));"
            "print(loaded); assert loaded == [], loaded; "
            "names = [n for n in servo.API if not callable(getattr(servo, n)) and n != 'lti']; assert names == [], names")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr

"""servo.load_run: a run folder back with named columns, units, config and summary."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

import servo
from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.errors import RecordingError
from servo.run.job import run_job

CFG = Config().replace(run={"duration_s": 0.05})


def test_npz_and_csv_folders_load_the_same_log(tmp_path):
    run_job(CFG, tmp_path / "npz", compensation="on", fast=True, log_formats=("npz",))
    run_job(CFG, tmp_path / "csv", compensation="on", fast=True, log_formats=("csv",))
    a, b = servo.load_run(tmp_path / "npz"), servo.load_run(tmp_path / "csv")
    header = (tmp_path / "csv" / "log_compensated.csv").read_text().split("\n", 1)[0]
    assert header.startswith("tick [-],t [s],r [m],x [m],v [m/s],u [A]")  # units in the CSV header
    assert a.labels == b.labels == ["compensated"]
    assert list(a.logs["compensated"]) == list(LOG_COLUMNS)
    for c in LOG_COLUMNS:
        assert np.array_equal(a.logs["compensated"][c], b.logs["compensated"][c])  # %.17g round trip
    assert a.rows("compensated").shape == (CFG.n_ticks, len(LOG_COLUMNS))
    assert a.units["u"] == "A" and a.units["x"] == "m" and a.meta["compensated"]["rows"] == CFG.n_ticks
    assert a.config.run.duration_s == CFG.run.duration_s
    assert a.summary == json.loads((tmp_path / "npz" / "summary.json").read_text())


def test_an_interrupted_folder_loads_without_a_summary_and_bad_folders_are_one_line(tmp_path):
    run_job(CFG, tmp_path / "r", compensation="on", fast=True)
    (tmp_path / "r" / "summary.json").unlink()
    assert servo.load_run(tmp_path / "r").summary is None
    with pytest.raises(RecordingError, match="no such run folder"):
        servo.load_run(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "log_compensated.journal").write_bytes(b"{}\n")
    with pytest.raises(RecordingError, match="servo recover"):
        servo.load_run(tmp_path / "empty")
    (tmp_path / "r" / "log_compensated.npz").write_bytes(b"not a zip")
    with pytest.raises(RecordingError, match="not a readable run log"):
        servo.load_run(tmp_path / "r")


@pytest.mark.slow
def test_a_run_of_a_plug_in_controller_loads(tmp_path, monkeypatch):
    """load_run once failed with "controller.kind must be one of pi, track, nss"."""
    import re

    from servo.cli import main
    from servo.controllers import KINDS

    doc = (Path(__file__).resolve().parents[1] / "docs" / "controllers.md").read_text()
    (tmp_path / "my_pd.py").write_text(re.findall(r"^```python\n(.*?)^```", doc, flags=re.S | re.M)[0])
    monkeypatch.chdir(tmp_path)
    # another test may have loaded its own my_pd in this process: this one loads afresh
    monkeypatch.delitem(sys.modules, "my_pd", raising=False)
    monkeypatch.setattr("servo.controllers.plugins._LOADED", set())
    before = dict(KINDS)
    try:
        assert main(["run", "--plugin", "my_pd", "--set", "controller.kind=pd", "--duration", "0.02", "--fast",
                     "--compensation", "on", "--quiet", "--out", "r"]) == 0  # fmt: skip
        KINDS.clear()
        KINDS.update(before)  # a fresh session: the plug-in not registered, nor loaded
        monkeypatch.setattr("servo.controllers.plugins._LOADED", set())
        run = servo.load_run(tmp_path / "r")
        assert run.config.controller.kind == "pd" and "de_dt" in run.logs["compensated"]
    finally:
        KINDS.clear()
        KINDS.update(before)

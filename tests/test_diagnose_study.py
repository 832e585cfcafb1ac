"""The detection study (``python -m studies.concealed``) runs on Dask through the
fleet's path (issue 13.6): on a local cluster of two workers it gives the runs of the
serial loop, in the same order, and the same tables."""
import pytest
import json

from studies.concealed import main, run_one, study_jobs, tables


def _untimed(runs):
    return [{k: v for k, v in r.items() if k != "seconds"} for r in runs]


@pytest.mark.slow
def test_a_small_study_on_two_dask_workers_gives_the_serial_loops_runs_and_tables(tmp_path, capsys):
    jobs = study_jobs(["hysteresis"], seeds=1, null_seeds=1)
    assert jobs[0] == (None, 0.0, 10_000) and len(jobs) == 6  # one null recording, five sizes of one seed
    serial = [run_one(j) for j in jobs]
    argv = ["--effects", "hysteresis", "--seeds", "1", "--null-seeds", "1", "--workers", "2", "--quiet",
            "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr()
    assert "6 runs on a local Dask cluster of 2 worker processes" in printed.out and printed.err == ""
    runs = json.loads((tmp_path / "study.json").read_text())
    assert _untimed(runs) == _untimed(serial)
    assert all(r["seconds"] > 0 for r in runs)
    timing = "\n\n6 diagnoses of 50 000-sample recordings"
    md = (tmp_path / "study.md").read_text()
    assert timing in md and md.split(timing)[0] == tables(serial).split(timing)[0]
    assert printed.out.startswith(md.split(timing)[0])
    # what the study is for: the effect is named at its clearly detectable sizes, the null recording is clean
    assert runs[0]["findings"] == [] and not any(runs[0]["locate"].values())
    big = [r for r in runs if r["effect"] == "hysteresis" and r["size"] >= 1e-4]
    assert len(big) == 2 and all("hysteresis" in r["findings"] for r in big)
    assert "| `hysteresis` (" in md and "| any finding (false alarm) | 0/1 |" in md

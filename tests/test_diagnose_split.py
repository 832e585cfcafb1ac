"""The held-out split (:func:`servo.diagnose.job.held_out_split`): the last quarter in
time, or of the usable rows where the last quarter in time has too few to test."""
import numpy as np
import pytest

from servo.diagnose.job import MIN_ROWS_PER_BLOCK, held_out_split


def test_the_split_is_in_time_where_the_test_part_has_usable_rows():
    valid = np.ones(1000, bool)
    valid[::7] = False
    train = held_out_split(valid, 0.25)
    assert train[:750].all() and not train[750:].any()


def test_a_test_part_without_usable_rows_takes_the_last_usable_quarter():
    valid = np.zeros(1000, bool)
    valid[:700] = True  # the end of the recording moves too fast to be read
    train = held_out_split(valid, 0.25)
    test = valid & ~train
    assert test.sum() == pytest.approx(0.25 * 700, abs=1)
    assert np.flatnonzero(test).min() > np.flatnonzero(valid & train).max()
    assert train[:525].all() and not train[525:].any()


def test_too_few_usable_rows_anywhere_keep_the_time_split():
    valid = np.zeros(1000, bool)
    valid[:3 * MIN_ROWS_PER_BLOCK] = True  # the refusal stays prepare's
    train = held_out_split(valid, 0.25)
    assert train[:750].all() and not train[750:].any()


@pytest.mark.slow
def test_an_open_loop_chirp_null_ending_too_fast_gets_a_verdict():
    """Development null 300014 (open loop, upward chirp, pink noise): its last quarter
    in time has 0-3 usable rows at every decimation from 10 to 4, and it was refused
    ("too few usable rows") where 600 training rows were usable; held out on its last
    usable rows it is `consistent`."""
    from servo.diagnose.job import diagnose
    from studies.proving.cases import Case, recording
    from studies.proving.study import KIND_RATE, KIND_SEEDS, grid_cell

    ctl, exc, noise = grid_cell("null", 0, 14)
    assert (ctl, exc) == ("force", "chirp")
    rec, _ = recording(Case("null", 0.0, ctl, exc, KIND_RATE, noise=noise), KIND_SEEDS["null"] + 14)
    D = diagnose(rec)
    assert D.verdict["verdict"] == "consistent", D.verdict.get("text")
    assert D.findings == []

"""A closed loop's steps: between moves the loop dithers the arm with the sensor noise it
feeds back, and the rows there carry a friction whose sign the filtered velocity cannot
tell (docs/diagnosis.md, section 1; docs/studies/2026-11-28-nulls-every-excitation.md).

At the default decimation (10) the ripple rule leaves under 1 % of the rows; the
diagnosis used to fall back to the noise rule's rows and read 12-28 x the floor,
`unexplained`, on every closed-loop steps null.  At a decimation of 3 the dither is
inside the band, the ripple rule leaves the moves (12-33 % of the rows), and those are
at the floor (on 35 and 51 too, where a breakaway is still named at rest: the held force
at each reference step's kick, docs/studies/2026-11-28-nulls-every-excitation.md).
Recordings of the independent proving ground (`studies/proving/`), on
development seeds (the second grid's nulls, offset 0).
"""
import pytest

from servo.diagnose.band import settings_for
from servo.diagnose.job import diagnose
from servo.diagnose.signals import RIPPLE_MIN_USABLE, make_signals
from studies.proving.cases import Case, recording
from studies.proving.study import KIND_RATE, KIND_SEEDS, grid_cell

def _null(j: int):
    ctl, exc, noise = grid_cell("null", 0, j)
    assert (ctl, exc) == ("pdi", "steps")
    rec, _ = recording(Case("null", 0.0, ctl, exc, KIND_RATE, noise=noise), KIND_SEEDS["null"] + j)
    return rec

@pytest.mark.slow
@pytest.mark.parametrize("j", [3, 19])
def test_closed_loop_steps_nulls_are_consistent_on_the_rows_whose_sign_is_known(j):
    rec = _null(j)
    fs = 1.0 / rec.dt
    default = make_signals(rec, settings_for(10, fs))
    # the dither: the noise rule leaves most rows, the ripple rule almost none
    assert default.noise_share > 0.4 and default.signed_share < 0.02
    D = diagnose(rec)
    sig = D.sig
    assert sig.settings.decimate < 10 and sig.v_ripple is not None  # the ripple rule's rows, no fallback
    assert RIPPLE_MIN_USABLE <= sig.usable_share < 0.3
    assert D.verdict["verdict"] == "consistent", D.verdict["text"]
    assert not D.findings
    assert D.verdict["baseline_checks"]["level"]["ratio"] < 1.1

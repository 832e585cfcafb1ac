"""The delay screen's rows (the force filtered once, interpolated at ``keep - shift``, the
exact chain at both ends) equal the exact chain's rows of the delayed input."""
import numpy as np
import pytest

from servo.diagnose.concealed import Scenario, concealed_recording
from servo.diagnose.delayed import EDGE_ROWS, DelayedForce, interp_at
from servo.diagnose.job import Options, prepare
from servo.diagnose.terms import TimeDelay
from servo.identify.regressors import RobustSettings


@pytest.mark.parametrize("q,duration", [(10, 1.0), (4, 0.5)])
def test_delayed_rows_equal_the_exact_chain(q, duration):
    rec, _ = concealed_recording("time_delay", 3e-6, seed=2, scenario=Scenario(duration_s=duration))
    sig = prepare(rec, RobustSettings(decimate=q), Options()).sig
    df = DelayedForce(sig, sig.u, 2 * q + 1)
    assert df.usable
    k = np.arange(sig.n, dtype=float)
    peak = np.abs(sig.force_rows(sig.u)).max()
    for shift in (-q, -1.75, -0.25, 0.5, 1.0, 3.0, 2 * q):
        u_d = TimeDelay.path.transform(sig.u, {"delay_s": shift * sig.dt}, sig.dt)
        assert np.array_equal(u_d, interp_at(sig.u, k, shift))
        exact = sig.force_rows(u_d)
        fast = df.rows(shift)
        assert np.abs(fast - exact).max() < 1e-12 * peak, shift
    # the interior alone is not enough: the filters' start-up differs at both ends
    interior = np.interp(sig.keep - 1.0, k, df.G)
    exact = sig.force_rows(interp_at(sig.u, k, 1.0))
    assert np.abs(interior - exact)[:EDGE_ROWS].max() > 1e-6 * peak


def test_a_short_recording_takes_the_exact_chain():
    rec, _ = concealed_recording(None, 0.0, seed=2, scenario=Scenario(duration_s=0.05))
    sig = prepare(rec, RobustSettings(decimate=4), Options(blocks=4)).sig
    df = DelayedForce(sig, sig.u, 9)
    assert not df.usable
    k = np.arange(sig.n, dtype=float)
    assert np.array_equal(df.rows(0.75), sig.force_rows(interp_at(sig.u, k, 0.75)))

"""The compiled biquad cascade is scipy.signal's: same output as ``sosfilt`` on the same
sections; and the track-following kind's anti-windup freezes its integrator at the limit."""
import numpy as np
from numba import float64, from_dtype, int64, njit
from scipy import signal

from kernels.biquad import MAX_SECTIONS, sos_cascade, sos_cascade_try, sos_commit
from servo.config import Config
from servo.runtime.controller import Controller

REC = np.dtype([("sos", "f8", (MAX_SECTIONS, 6)), ("z", "f8", (MAX_SECTIONS, 2)), ("z2", "f8", (MAX_SECTIONS, 2))])
rec_t = from_dtype(REC)


@njit(float64[::1](rec_t, int64, float64[::1]))
def run(r, n, x):
    y = np.empty_like(x)
    for k in range(x.shape[0]):
        y[k] = sos_cascade(r.sos, r.z, n, x[k])
    return y


@njit(float64[::1](rec_t, int64, float64[::1]))
def run_try_commit(r, n, x):
    y = np.empty_like(x)
    for k in range(x.shape[0]):
        y[k] = sos_cascade_try(r.sos, r.z, r.z2, n, x[k])
        sos_commit(r.z, r.z2, n)
    return y


def test_the_cascade_is_scipy_sosfilt():
    sos = signal.butter(6, 0.1, output="sos")  # three sections
    sos = np.vstack([sos, signal.tf2sos(*signal.iirnotch(0.3, 5.0))])  # and a notch
    x = np.random.default_rng(1).standard_normal(5000)
    want = signal.sosfilt(sos, x)
    for fn in (run, run_try_commit):
        r = np.zeros(1, REC)
        r["sos"][0, : len(sos)] = sos
        got = fn(r[0], len(sos), x)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_try_without_commit_leaves_the_states():
    sos = signal.butter(2, 0.2, output="sos")
    r = np.zeros(1, REC)
    r["sos"][0, :1] = sos
    run(r[0], 1, np.ones(10))
    before = r["z"].copy()
    sos_cascade_try(r[0]["sos"], r[0]["z"], r[0]["z2"], 1, 5.0)
    assert np.array_equal(r["z"], before) and not np.array_equal(r["z2"][0, :1], before[0, :1])


def test_the_track_kinds_integrator_stops_at_the_output_limit():
    """Conditional integration: while the output is clamped and the error pushes further into
    the limit, the slow cascade (with the integrator) keeps its states."""
    cfg = Config().replace(controller={"kind": "track", "track": {"output_limit": 1e-3}})
    ctl = Controller(cfg, compensation=False)  # u = u_n: the kind's own limit shows
    ctl.start(0.0, 0.0, 0.0)
    for _ in range(5):
        u = ctl.tick(0.0, 0.0, 1e-3, 0.0)  # a 1 mm error: far beyond what 1 mA can hold
    assert u == 1e-3 and ctl.state[0]["sat"] == 1.0
    frozen = ctl.state[0]["z_slow"].copy()
    for _ in range(100):
        ctl.tick(0.0, 0.0, 1e-3, 0.0)
    assert np.array_equal(ctl.state[0]["z_slow"], frozen)
    ctl.tick(2e-3, 0.0, 1e-3, 0.0)  # the error reverses: the states move again
    ctl.tick(2e-3, 0.0, 1e-3, 0.0)
    assert not np.array_equal(ctl.state[0]["z_slow"], frozen)

"""References measured in the same run: the controller tick and plant step in C (built
now with the system C compiler, called through ctypes), and the controller tick in pure
Python.  First that they compute the same numbers as the Numba kernels (otherwise a time
ratio means nothing), then their per-sample figures and the ratios.

Ratios are timed in adjacent pairs (:func:`bench.timing.paired`): on a loaded host
absolute times move by 2x, the ratio of two calls made back to back does not.
"""
import numpy as np
import pytest

from bench import loops, pyref
from bench import workload as w
from bench.budgets import NUMBA_OVER_C_EVERY_TERM_MAX, NUMBA_OVER_C_MAX, NUMBA_OVER_C_TRACK_MAX, PYTHON_OVER_NUMBA_MIN
from bench.timing import paired, per_sample_ns
from servo.config import Config

ROUNDS = 15

#: Configurations that take every branch of the C/Python transcriptions.
CASES = {
    "default": {},
    "alpha 1.5, estimated velocity": {"drive": {"alpha": 1.5}, "compensator": {"alpha": 1.5},
                                      "controller": {"velocity_source": "estimated", "direction_deadband": 5e-5}},
    "alpha 0.6, no velocity sensor": {"drive": {"alpha": 0.6, "measures_velocity": False}, "compensator": {"alpha": 0.6}},
    "compensator off, tight limits": {"compensator": {"enabled": False},
                                      "controller": {"pi": {"holding_limit": 2e-3}, "current_limit": 3e-3}},
    "Coulomb/Stribeck, cogging, kf, delay 2.25 samples, stops": {
        "drive": {"Fc": 1e-3, "Fs": 1.5e-3, "fc_asymmetry": 0.2, "b_asymmetry": -0.1, "cogging": 1e-4,
                  "kf_linear": 0.05, "kf_quadratic": -0.1, "input_delay_s": 45e-6, "stroke": 25e-6,
                  "mode_hz": [], "mode_zeta": [], "mode_gain": [], "position_quantum": 0.0}},
    "every compensator term, authority and kf clips": {"compensator": w.EVERY_TERM},
}  # fmt: skip
#: Cases asserted equal to the bit (the others within ``same``'s relative 1e-12, and recorded).
BITWISE_CASES = ["every compensator term, authority and kf clips"]
#: The cases the pure-Python reference covers (it transcribes the paper's tick, eq. 6-9, without the
#: terms of kernels/cancel.py).
PYTHON_CASES = ["default", "alpha 1.5, estimated velocity", "alpha 0.6, no velocity sensor", "compensator off, tight limits"]


def same(a, b, rtol=1e-12):
    """Largest relative difference of ``a`` and ``b``, asserting it is within ``rtol``."""
    a, b = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    assert np.array_equal(np.isnan(a), np.isnan(b))
    a, b = a[~np.isnan(a)], b[~np.isnan(b)]
    scale = np.maximum(np.abs(a), np.abs(b))
    rel = np.where(scale > 0, np.abs(a - b) / np.where(scale > 0, scale, 1.0), 0.0)
    worst = float(rel.max(initial=0.0))
    assert worst <= rtol, f"relative difference {worst:.3g} > {rtol:g}"
    return worst


def records(rec):
    """Every float64 of a record array (nested arrays included), in layout order."""
    return np.frombuffer(np.ascontiguousarray(rec).tobytes(), dtype=np.float64)


@pytest.mark.parametrize("case", list(CASES))
def test_c_computes_what_numba_computes(cref_lib, record, case):
    """Controller alone, plant alone, and the closed loop (plant_measure -> controller_tick
    -> plant_step) for 20 000 samples: the same numbers, state and every output."""
    cfg = Config().replace(**CASES[case])
    worst = 0.0
    xin = w.controller_inputs(cfg)
    a, b = w.controller(cfg), w.controller(cfg)
    worst = max(worst, same(loops.loop_controller_tick(20_000, xin, *a.records()),
                            cref_lib.loop_controller_tick(20_000, xin, *b.records())))  # fmt: skip
    worst = max(worst, same(records(a.stage_state), records(b.stage_state)), same(records(a.state), records(b.state)))
    uin = w.plant_inputs(cfg)
    pa, pb = w.plant(cfg), w.plant(cfg)
    worst = max(worst, same(loops.loop_plant_step(20_000, uin, pa.state, pa.params, pa.q, pa.mab, pa.ubuf),
                            cref_lib.loop_plant_step(20_000, uin, pb)))  # fmt: skip
    worst = max(worst, same(records(pa.state), records(pb.state)), same(pa.q, pb.q), same(pa.ubuf, pb.ubuf))
    # the closed loop, sample by sample through the single-step entry points
    from kernels.plant import plant_measure, plant_step

    ref, noise = w.closed_loop_inputs(cfg), w.noise()
    pa, pb, a, b = w.plant(cfg), w.plant(cfg), w.controller(cfg), w.controller(cfg)
    out = np.empty((2, 20_000, 3))
    for k in range(20_000):
        j = k % ref.shape[0]
        x, v = plant_measure(pa.state, pa.params, pa.q, pa.gain, noise[j, 0], noise[j, 1])
        u = a.tick(x, v, ref[j, 0], ref[j, 1])
        plant_step(pa.state, pa.params, pa.q, pa.mab, pa.ubuf, u, ref[j, 2])
        out[0, k] = x, v, u
        x, v = cref_lib.plant_measure(pb, noise[j, 0], noise[j, 1])
        u = cref_lib.controller_tick(b, x, v, ref[j, 0], ref[j, 1])
        cref_lib.plant_step(pb, u, ref[j, 2])
        out[1, k] = x, v, u
    worst = max(worst, same(out[0], out[1]), same(records(a.stage_state), records(b.stage_state)),
                same(records(a.state), records(b.state)))
    assert np.ptp(out[0, :, 0]) > 1e-6  # the loop moved the arm
    if case in BITWISE_CASES:
        assert worst == 0.0, f"{case}: C and Numba differ (relative {worst:.3g}): they are transcribed to the bit"
    record.check(f"C == Numba: {case}", max_relative_difference=worst, bitwise=worst == 0.0)


@pytest.mark.parametrize("terms", ["paper", "every term"])
def test_c_computes_what_numba_computes_for_the_track_following_tick(cref_lib, record, terms):
    """The track-following kind (two cascades of biquads at two rates, anti-windup) on its
    stage: the same numbers in C and Numba, outputs and every state."""
    cfg = Config().replace(controller={"kind": "track", "track": {"pes_every": 2}},
                           compensator=w.EVERY_TERM if terms == "every term" else {})  # fmt: skip
    xin = w.controller_inputs(cfg)
    a, b = w.controller(cfg), w.controller(cfg)
    worst = same(loops.loop_track_tick(20_000, xin, *a.records()), cref_lib.loop_track_tick(20_000, xin, *b.records()))
    worst = max(worst, same(records(a.stage_state), records(b.stage_state)), same(records(a.state), records(b.state)))
    assert np.any(a.state[0]["z_slow"] != 0.0)  # the cascades ran
    if terms == "every term":
        assert worst == 0.0, f"C and Numba differ (relative {worst:.3g}): they are transcribed to the bit"
    record.check(f"C == Numba: track-following tick, {terms}", max_relative_difference=worst, bitwise=worst == 0.0)


def test_c_computes_what_numba_computes_sample_by_sample_with_every_term_on(cref_lib, record):
    """The PI tick on its stage with every term of kernels/cancel.py on and both authority
    clips, one sample at a time through the runtime's tick (``Controller.tick``) and through C: every
    command, every compensation current and the state after each sample are the same bits.

    The inputs (:func:`bench.workload.controller_inputs`) are arranged so that every
    branch is taken, and this is checked, not assumed: direction reversals, the periodic
    force swept over many of its periods, kf(x) clipped at both ends of the motion and not
    in between, |u_c| held at the authority on some samples and not on others, the Coulomb
    term acting (moving) and not (within the direction deadband)."""
    from kernels.cancel import force_constant

    cfg = Config().replace(compensator=w.EVERY_TERM)
    xin = w.controller_inputs(cfg)
    a, b = w.controller(cfg), w.controller(cfg)
    p = a.stage_params[0]
    n = 2 * xin.shape[0]  # the table twice: the state carried into the second pass differs from the first
    out = np.empty((2, n, 3))
    state = np.empty((2, n, len(records(a.stage_state)) + 1))
    for k in range(n):
        x, v, r, u_exc = xin[k % xin.shape[0]]
        out[0, k] = a.tick(x, v, r, u_exc), a.stage_state[0]["u_c"], a.stage_state[0]["s"]
        out[1, k] = cref_lib.controller_tick(b, x, v, r, u_exc), b.stage_state[0]["u_c"], b.stage_state[0]["s"]
        state[0, k] = np.r_[records(a.stage_state), a.state[0]["integ"]]
        state[1, k] = np.r_[records(b.stage_state), b.state[0]["integ"]]
    assert np.array_equal(out[0].view(np.uint64), out[1].view(np.uint64)), "C and Numba commands differ"
    assert np.array_equal(state[0].view(np.uint64), state[1].view(np.uint64)), "C and Numba states differ"
    # every branch was taken
    u_c, s = out[0, :, 1], out[0, :, 2]
    x = np.tile(xin[:, 0], 2)
    kf = np.array([force_constant(xi, p["kf1"], p["kf2"], p["kf_stroke"]) for xi in x])
    moving = np.abs(np.tile(xin[:, 1], 2)) > p["v_deadband"]
    coverage = dict(
        reversals=int(np.count_nonzero(np.diff(s))),
        periods_swept=float(np.ptp(x) / p["per_period"]),
        kf_clipped_high=float(np.mean(kf > p["kf_hi"])), kf_clipped_low=float(np.mean(kf < p["kf_lo"])),
        authority_held=float(np.mean(np.abs(u_c) == p["uc_max"])),
        coulomb_acting=int(np.count_nonzero(moving)), coulomb_resting=int(np.count_nonzero(~moving)),
    )  # fmt: skip
    assert coverage["reversals"] >= 20, coverage
    assert coverage["periods_swept"] >= 10, coverage
    assert 0.01 < coverage["kf_clipped_high"] < 0.5 and 0.01 < coverage["kf_clipped_low"] < 0.5, coverage
    assert 0.01 < coverage["authority_held"] < 0.9, coverage
    assert coverage["coulomb_acting"] > n // 10 and coverage["coulomb_resting"] >= 10, coverage
    assert np.all(np.abs(u_c) <= p["uc_max"])
    record.check("C == Numba: PI tick, every compensator term, sample by sample", bitwise=True, samples=n, **coverage)


@pytest.mark.parametrize("case", PYTHON_CASES)
def test_python_computes_what_numba_computes(record, case):
    cfg = Config().replace(**CASES[case])
    xin = w.controller_inputs(cfg)
    a, b = w.controller(cfg), w.controller(cfg)
    recs = [pyref.Record(r) for r in b.records()]
    rows = [tuple(map(float, r)) for r in xin]
    worst = same(loops.loop_controller_tick(10_000, xin, *a.records()), pyref.loop_controller_tick(10_000, rows, recs))
    worst = max(worst, same(records(a.stage_state), records(recs[0].to_array(a.stage_state))),
                same(records(a.state), records(recs[2].to_array(a.state))))
    record.check(f"Python == Numba: {case}", max_relative_difference=worst, bitwise=worst == 0.0)


# ---- per-sample figures of the references -------------------------------------------------


def test_controller_tick_c(benchmark, cfg, cref_lib, record):
    ctl, xin, n = w.controller(cfg), w.controller_inputs(cfg), 100_000
    ns = per_sample_ns(benchmark, cref_lib.loop_controller_tick, n, ROUNDS, setup=lambda: ((n, xin, *ctl.records()), {}))
    record.figure("controller_tick_c", ns)


def test_controller_tick_every_term_c(benchmark, cfg, cref_lib, record):
    ctl, xin, n = w.controller(cfg.replace(compensator=w.EVERY_TERM)), w.controller_inputs(cfg), 100_000
    ns = per_sample_ns(benchmark, cref_lib.loop_controller_tick, n, ROUNDS, setup=lambda: ((n, xin, *ctl.records()), {}))
    record.figure("controller_tick_every_term_c", ns)


def test_plant_step_c(benchmark, cfg, cref_lib, record):
    uin, n = w.plant_inputs(cfg), 20_000
    ns = per_sample_ns(benchmark, cref_lib.loop_plant_step, n, ROUNDS, setup=lambda: ((n, uin, w.plant(cfg)), {}))
    record.figure("plant_step_c", ns)


def test_closed_loop_kernels(benchmark, cfg, record):
    """plant_measure -> controller_tick -> plant_step in one compiled loop, no logging."""
    ref, noise, n = w.closed_loop_inputs(cfg), w.noise(), 20_000

    def setup():
        p, c = w.plant(cfg), w.controller(cfg)
        return (n, ref, noise, p.state, p.params, p.q, p.mab, p.gain, p.ubuf, *c.records()), {}

    record.figure("closed_loop_kernels", per_sample_ns(benchmark, loops.loop_closed, n, ROUNDS, setup=setup))


def test_closed_loop_c(benchmark, cfg, cref_lib, record):
    ref, noise, n = w.closed_loop_inputs(cfg), w.noise(), 20_000

    def setup():
        c = w.controller(cfg)
        return (n, ref, noise, w.plant(cfg), *c.records()), {}

    record.figure("closed_loop_c", per_sample_ns(benchmark, cref_lib.loop_closed, n, ROUNDS, setup=setup))


def test_controller_tick_python(benchmark, cfg, record):
    ctl, n = w.controller(cfg), 2_000
    rows = [tuple(map(float, r)) for r in w.controller_inputs(cfg)]

    def setup():
        return (n, rows, [pyref.Record(r) for r in ctl.records()]), {}

    record.figure("controller_tick_python", per_sample_ns(benchmark, pyref.loop_controller_tick, n, 9, setup=setup))


# ---- ratios, timed in adjacent pairs ---------------------------------------------------------


def _numba_c(cfg, cref_lib, what):
    if what == "controller_tick_every_term":
        what, cfg = "controller_tick", cfg.replace(compensator=w.EVERY_TERM)
    if what == "controller_tick":
        xin, a, b, n = w.controller_inputs(cfg), w.controller(cfg), w.controller(cfg), 5_000
        return (lambda: loops.loop_controller_tick(n, xin, *a.records()),
                lambda: cref_lib.loop_controller_tick(n, xin, *b.records()), n)  # fmt: skip
    if what == "track_tick":
        cfg = cfg.replace(controller={"kind": "track"})
        xin, a, b, n = w.controller_inputs(cfg), w.controller(cfg), w.controller(cfg), 5_000
        return (lambda: loops.loop_track_tick(n, xin, *a.records()),
                lambda: cref_lib.loop_track_tick(n, xin, *b.records()), n)  # fmt: skip
    if what == "plant_step":
        uin, pa, pb, n = w.plant_inputs(cfg), w.plant(cfg), w.plant(cfg), 1_000
        return (lambda: loops.loop_plant_step(n, uin, pa.state, pa.params, pa.q, pa.mab, pa.ubuf),
                lambda: cref_lib.loop_plant_step(n, uin, pb), n)  # fmt: skip
    ref, noise, n = w.closed_loop_inputs(cfg), w.noise(), 1_000
    pa, pb, a, b = w.plant(cfg), w.plant(cfg), w.controller(cfg), w.controller(cfg)
    return (lambda: loops.loop_closed(n, ref, noise, pa.state, pa.params, pa.q, pa.mab, pa.gain, pa.ubuf, *a.records()),
            lambda: cref_lib.loop_closed(n, ref, noise, pb, *b.records()), n)  # fmt: skip


@pytest.mark.parametrize("what", ["controller_tick", "controller_tick_every_term", "track_tick", "plant_step",
                                  "closed_loop"])  # fmt: skip
def test_numba_over_c_ratio(cfg, cref_lib, record, what):
    """Numba/C per-sample time ratio on the same arithmetic: near 1 (at most 2.5; the tick
    with every compensator term, issue 14's goal 1.1: at most 1.75, the worst seen x 1.5;
    the track-following tick, usually 1.6-1.8: at most 3.5, ``bench/budgets.py``)."""
    numba_fn, c_fn, n = _numba_c(cfg, cref_lib, what)
    bound = {"controller_tick_every_term": NUMBA_OVER_C_EVERY_TERM_MAX,
             "track_tick": NUMBA_OVER_C_TRACK_MAX}.get(what, NUMBA_OVER_C_MAX)
    r = paired(numba_fn, c_fn, pairs=201)
    record.ratio(f"numba_over_c_{what}", r.ratio, f"<= {bound:g}", numba_ns=r.a_ns / n, c_ns=r.b_ns / n)
    assert r.ratio <= bound, (f"{what}: Numba takes {r.ratio:.2f}x the time of C "
                              f"({r.a_ns / n:.1f} vs {r.b_ns / n:.1f} ns per sample)")  # fmt: skip


def test_python_over_numba_ratio(cfg, record):
    """Pure Python/Numba per-sample time ratio of the controller tick: at least 20."""
    xin, a = w.controller_inputs(cfg), w.controller(cfg)
    rows = [tuple(map(float, r)) for r in xin]
    recs = [pyref.Record(r) for r in a.records()]
    b = w.controller(cfg)
    n_py, n_nb = 200, 20_000
    r = paired(lambda: pyref.loop_controller_tick(n_py, rows, recs),
               lambda: loops.loop_controller_tick(n_nb, xin, *b.records()), pairs=61)  # fmt: skip
    ratio = (r.a_ns / n_py) / (r.b_ns / n_nb)
    record.ratio("python_over_numba_controller_tick", ratio, f">= {PYTHON_OVER_NUMBA_MIN:g}",
                 python_ns=r.a_ns / n_py, numba_ns=r.b_ns / n_nb)  # fmt: skip
    assert ratio >= PYTHON_OVER_NUMBA_MIN, f"the compiled controller tick is only {ratio:.1f}x faster than pure Python"

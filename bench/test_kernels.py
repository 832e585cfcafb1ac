"""Each kernel alone, and the full controller tick, per sample inside a compiled loop.

Budgets (fractions of the sample period) are in :mod:`bench.budgets`; each test asserts
the median over rounds of (round time / samples per round).
"""
import numpy as np
import pytest

from bench import loops
from bench import workload as w
from bench.budgets import BUDGETS, EVERY_TERM_OVER_PAPER_MAX, KIND_OVER_PI_TICK_MAX
from bench.timing import paired, per_sample_ns

ROUNDS = 15


def _assert_budget(cfg, name, ns, budget):
    limit = BUDGETS[budget].ns(cfg)
    assert ns <= limit, f"{name}: {ns:.1f} ns per sample, over its budget of {limit:.0f} ns ({BUDGETS[budget].fraction:g} of the period)"


def test_controller_tick(benchmark, cfg, record):
    """Dahl update + compensator + PI holding loop + limits, compensator on."""
    ctl, xin, n = w.controller(cfg), w.controller_inputs(cfg), 100_000
    ns = per_sample_ns(benchmark, loops.loop_controller_tick, n, ROUNDS, setup=lambda: ((n, xin, *ctl.records()), {}))
    record.figure("controller_tick", ns, "controller_tick")
    _assert_budget(cfg, "controller tick", ns, "controller_tick")


def test_controller_tick_uncompensated(benchmark, cfg, record):
    """The same tick with the compensator off (the PI loop alone, plus the Dahl update)."""
    ctl, xin, n = w.controller(cfg, compensation=False), w.controller_inputs(cfg), 100_000
    ns = per_sample_ns(benchmark, loops.loop_controller_tick, n, ROUNDS, setup=lambda: ((n, xin, *ctl.records()), {}))
    record.figure("controller_tick_uncompensated", ns, "controller_tick")
    _assert_budget(cfg, "controller tick (uncompensated)", ns, "controller_tick")


def test_controller_tick_every_term(benchmark, cfg, record):
    """The PI tick with every compensator term on (:data:`bench.workload.EVERY_TERM`: the
    terms of kernels/cancel.py, kf(x) and both authority clips, each branch taken): its
    figure, recorded against issue 14's 100 ns (1/200 of the period), and that budget
    asserted in a form the host's load cancels from: against the paper's tick (eq. 6-9)
    timed in adjacent pairs, at most :data:`EVERY_TERM_OVER_PAPER_MAX` (~100 ns over the
    paper tick's ~24 ns).  The figure itself is not asserted: at load 7 on the 2 cores it
    measured 252 ns against 68-80 ns calm (docs/realtime.md)."""
    xin, n = w.controller_inputs(cfg), 100_000
    ctl = w.controller(cfg.replace(compensator=w.EVERY_TERM))
    ns = per_sample_ns(benchmark, loops.loop_controller_tick, n, ROUNDS, setup=lambda: ((n, xin, *ctl.records()), {}))
    record.figure("controller_tick_every_term", ns, "controller_tick_every_term")
    m = 5_000
    a, b = w.controller(cfg.replace(compensator=w.EVERY_TERM)), w.controller(cfg)
    r = paired(lambda: loops.loop_controller_tick(m, xin, *a.records()),
               lambda: loops.loop_controller_tick(m, xin, *b.records()), pairs=201)  # fmt: skip
    record.ratio("every_term_over_paper_tick", r.ratio, f"<= {EVERY_TERM_OVER_PAPER_MAX:g}",
                 every_term_ns=r.a_ns / m, paper_ns=r.b_ns / m)  # fmt: skip
    assert r.ratio <= EVERY_TERM_OVER_PAPER_MAX, (
        f"the tick with every compensator term costs {r.ratio:.2f}x the paper's tick "
        f"({r.a_ns / m:.1f} vs {r.b_ns / m:.1f} ns per sample), over {EVERY_TERM_OVER_PAPER_MAX:g}")


@pytest.mark.parametrize("kind", ["track", "nss"])
def test_controller_tick_of_every_kind(benchmark, cfg, record, kind):
    """The other controller kinds on the same stage (compensator on): their figure,
    recorded against the controller tick's budget, and that budget asserted in a form
    the host's load cancels from: against the PI kind's tick timed in adjacent pairs, at
    most :data:`KIND_OVER_PI_TICK_MAX`.  (The figure alone failed its 200 ns budget at
    229 ns at load 13, where the ratio holds: :data:`bench.budgets.KIND_OVER_PI_TICK_MAX`.)"""
    ctl = w.controller(cfg.replace(controller={"kind": kind}))
    xin, n = w.controller_inputs(cfg), 100_000
    loop = {"track": loops.loop_track_tick, "nss": loops.loop_nss_tick}[kind]
    ns = per_sample_ns(benchmark, loop, n, ROUNDS, setup=lambda: ((n, xin, *ctl.records()), {}))
    record.figure(f"controller_tick_{kind}", ns, "controller_tick")
    m, pi = 5_000, w.controller(cfg)
    r = paired(lambda: loop(m, xin, *ctl.records()), lambda: loops.loop_controller_tick(m, xin, *pi.records()),
               pairs=201)  # fmt: skip
    record.ratio(f"{kind}_over_pi_tick", r.ratio, f"<= {KIND_OVER_PI_TICK_MAX:g}", kind_ns=r.a_ns / m, pi_ns=r.b_ns / m)
    assert r.ratio <= KIND_OVER_PI_TICK_MAX, (
        f"the {kind} controller's tick costs {r.ratio:.2f}x the PI tick ({r.a_ns / m:.1f} vs {r.b_ns / m:.1f} ns "
        f"per sample), over {KIND_OVER_PI_TICK_MAX:g}")


@pytest.mark.parametrize("alpha", [1.0, 1.5])
def test_dahl_update(benchmark, cfg, record, alpha):
    m, k, n = w.motion(cfg), cfg.compensator, 200_000
    xin = np.ascontiguousarray(np.column_stack([m.x, m.s]))
    ns = per_sample_ns(benchmark, loops.loop_dahl_update, n, ROUNDS, setup=lambda: ((n, xin, k.sigma, k.Ha, alpha), {}))
    record.figure(f"dahl_update_alpha_{alpha:g}", ns, "dahl_update")
    _assert_budget(cfg, f"dahl_update (alpha={alpha:g})", ns, "dahl_update")


def test_compensate(benchmark, cfg, record):
    m, k, n = w.motion(cfg), cfg.compensator, 1_000_000
    regime = (np.abs(m.v) > k.fast_on_speed).astype(float)
    H = k.Ha * np.tanh(m.x * k.sigma / k.Ha)
    xin = np.ascontiguousarray(np.column_stack([regime, m.x, m.v, m.s, H]))
    kp = np.array([k.B, k.sliding_level, k.K, k.h0])
    ns = per_sample_ns(benchmark, loops.loop_compensate, n, ROUNDS, setup=lambda: ((n, xin, kp), {}))
    record.figure("compensate", ns, "compensate")
    _assert_budget(cfg, "compensate", ns, "compensate")


def test_holding_pi(benchmark, cfg, record):
    m, c, n = w.motion(cfg), cfg.controller.pi, 1_000_000
    xin = np.ascontiguousarray(np.column_stack([-m.x, -c.setpoint_weight * m.x, m.v]))
    g = np.array([c.kp, c.ki, c.kd, cfg.dt, -c.holding_limit, c.holding_limit])
    ns = per_sample_ns(benchmark, loops.loop_holding_pi, n, ROUNDS, setup=lambda: ((n, xin, g), {}))
    record.figure("holding_pi", ns, "holding_pi")
    _assert_budget(cfg, "holding_pi", ns, "holding_pi")


def test_plant_step(benchmark, cfg, record):
    """The simulated drive: default config (10 us input delay: two constant-input
    intervals per sample, 2 RK4 sub-steps each, six flexible modes)."""
    uin, n = w.plant_inputs(cfg), 20_000

    def setup():
        p = w.plant(cfg)  # a fresh arm each round: the open-loop drift stays small
        return (n, uin, p.state, p.params, p.q, p.mab, p.ubuf), {}

    ns = per_sample_ns(benchmark, loops.loop_plant_step, n, ROUNDS, setup=setup)
    record.figure("plant_step", ns, "plant_step")
    _assert_budget(cfg, "plant_step", ns, "plant_step")


def test_plant_measure(benchmark, cfg, record):
    p, noise, n = w.plant(cfg), w.noise(), 500_000
    ns = per_sample_ns(benchmark, loops.loop_plant_measure, n, ROUNDS, setup=lambda: ((n, noise, p.state, p.params, p.q, p.gain), {}))
    record.figure("plant_measure", ns, "plant_measure")
    _assert_budget(cfg, "plant_measure", ns, "plant_measure")


def test_shift_in(benchmark, cfg, record):
    """The link's command queue at a 3-tick latency."""
    uin, buf, n = w.plant_inputs(cfg), np.zeros(3), 500_000
    ns = per_sample_ns(benchmark, loops.loop_shift_in, n, ROUNDS, setup=lambda: ((n, uin, buf), {}))
    record.figure("shift_in", ns, "shift_in")
    _assert_budget(cfg, "shift_in", ns, "shift_in")

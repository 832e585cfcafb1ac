"""The ``steps`` scenario's reference and disturbance, in any window of ticks, against
their definitions (evaluated tick by tick)."""
import math

import numpy as np

from servo.config import Config
from servo.scenarios import scenario_inputs


def test_reference_and_disturbance_follow_their_definitions_in_every_window():
    cfg = Config().replace(run={"duration_s": 0.5}, scenario={
        "step_times": [0.01, 0.01, 0.02, 0.3], "step_positions": [1e-7, 3e-7, -2e-6, 5e-6],
        "disturbance_start": 0.2})  # fmt: skip
    inp = scenario_inputs(cfg)
    steps = [(int(round(t / cfg.dt)), p) for t, p in zip(cfg.scenario.step_times, cfg.scenario.step_positions)]
    s = cfg.scenario
    for base in range(0, cfg.n_ticks, 1000):  # windows before, across and after each step and the start
        ticks = np.arange(base, base + 1000)
        r, d = inp.reference(ticks), inp.disturbance(ticks)
        for i, k in enumerate(ticks):
            want = 0.0
            for kk, p in steps:  # the last step at or before k; of two at one tick, the later
                if k >= kk:
                    want = p
            assert r[i] == want
            t = k * cfg.dt
            dk = 0.0 if t < s.disturbance_start else s.disturbance_amplitude * math.sin(
                2.0 * math.pi * s.disturbance_hz * (t - s.disturbance_start))  # fmt: skip
            assert abs(d[i] - dk) <= 1e-15
    assert inp.disturbance(np.arange(0, 10)).tobytes() == np.zeros(10).tobytes()

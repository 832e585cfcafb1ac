"""Scenario inputs of a run, one value per tick: reference, excitation, disturbance.

Computed once for the whole run, as arrays, so that the tick-by-tick path and the
compiled fast path read the very same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servo.config import Config


@dataclass
class Inputs:
    """Per-tick inputs (each shape (n_ticks,)).

    ``r``: reference position relative to the holding position, m.
    ``u_exc``: excitation current added to the holding loop's output, A.
    ``d``: disturbance force on the arm (simulated drive only), A.
    """

    r: np.ndarray
    u_exc: np.ndarray
    d: np.ndarray

    @classmethod
    def zeros(cls, n: int) -> "Inputs":
        return cls(np.zeros(n), np.zeros(n), np.zeros(n))


def step_reference(times_s, positions_m, n: int, dt: float) -> np.ndarray:
    """Piecewise-constant reference (m): ``positions_m[i]`` from ``times_s[i]`` on, 0 before."""
    r = np.zeros(n)
    for t, pos in zip(times_s, positions_m):
        k = int(round(t / dt))
        if k < n:
            r[k:] = pos
    return r


def sine_disturbance(amplitude: float, hz: float, start_s: float, n: int, dt: float) -> np.ndarray:
    """``amplitude*sin(2*pi*hz*(t - start_s))`` from ``start_s`` on, 0 before (A)."""
    t = np.arange(n) * dt
    d = amplitude * np.sin(2.0 * np.pi * hz * (t - start_s))
    d[t < start_s] = 0.0
    return d


def scenario_inputs(cfg: Config) -> Inputs:
    """The ``servo run`` scenario of ``cfg.scenario``: hold, steps, then a disturbance."""
    s, n, dt = cfg.scenario, cfg.n_ticks, cfg.dt
    return Inputs(
        r=step_reference(s.step_times, s.step_positions, n, dt),
        u_exc=np.zeros(n),
        d=sine_disturbance(s.disturbance_amplitude, s.disturbance_hz, s.disturbance_start, n, dt),
    )


def segments(cfg: Config) -> list[tuple[str, float, float]]:
    """Named time segments of the scenario: hold, each step, the disturbance."""
    s, end = cfg.scenario, cfg.run.duration_s
    marks = [(0.0, "hold")] + [(t, f"step {i + 1}") for i, t in enumerate(s.step_times)]
    if s.disturbance_amplitude > 0.0:
        marks.append((s.disturbance_start, "disturbance"))
    marks = sorted((t, name) for t, name in marks if t < end)
    return [(name, t0, (marks[i + 1][0] if i + 1 < len(marks) else end)) for i, (t0, name) in enumerate(marks)]

"""Time-domain figures of merit of a run: step response, segment RMS, tick timing."""
from __future__ import annotations

import numpy as np

from servo.runtime.durations import Durations


def step_metrics(t: np.ndarray, x: np.ndarray, t_step: float, t_end: float, x0: float, x1: float, band: float = 0.05) -> dict:
    """Overshoot and settling of one reference step from ``x0`` to ``x1`` (m) at
    ``t_step`` (s), judged up to ``t_end`` (s).

    Returns ``size_m``; ``overshoot_pct`` (peak beyond the target, % of the step);
    ``settling_ms`` (time after the step of the last sample outside ``+-band`` of the
    step around the target; None if it has not settled by ``t_end``).
    """
    m = (t >= t_step) & (t < t_end)
    size = x1 - x0
    y = (x[m] - x0) / size  # normalised: 0 before, 1 at target
    tt = t[m] - t_step
    outside = np.flatnonzero(np.abs(y - 1.0) > band)
    if outside.size and outside[-1] == y.size - 1:
        settle = None
    else:
        settle = float(tt[outside[-1] + 1]) * 1e3 if outside.size else 0.0
    return {"size_m": size, "overshoot_pct": float(max(y.max() - 1.0, 0.0) * 100), "settling_ms": settle}


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def tick_timing(ticks: Durations, period_s: float) -> dict:
    """Per-tick compute time (us): the first tick (after ``configure``), median, p99, max;
    overruns = ticks longer than the period."""
    return {
        "tick_us_first": ticks.first / 1e3,
        "tick_us_median": ticks.quantile(0.5) / 1e3,
        "tick_us_p99": ticks.quantile(0.99) / 1e3,
        "tick_us_max": ticks.max / 1e3,
        "overruns": ticks.count_above(period_s * 1e9),
    }

"""Time-domain figures of merit of a run: step response, segment RMS, tick timing."""
from __future__ import annotations

import numpy as np

from servo.runtime.durations import Durations


class StepResponse:
    """Overshoot and settling of one reference step from ``x0`` to ``x1`` (m) at
    ``t_step`` (s), judged up to ``t_end`` (s), accumulated over chunks of samples given
    in time order (:meth:`update`), so a log of any length needs no more memory.

    :meth:`result`: ``size_m``; ``overshoot_pct`` (peak beyond the target, % of the
    step); ``settling_ms`` (time after the step of the first sample after the last one
    outside ``+-band`` of the step around the target; None if it has not settled by
    ``t_end``, 0 if it never left the band).
    """

    def __init__(self, t_step: float, t_end: float, x0: float, x1: float, band: float = 0.05):
        self.t_step, self.t_end, self.x0, self.x1, self.band = t_step, t_end, x0, x1, band
        self.peak = -np.inf
        self.left_band = False
        self.pending = False  # the last sample seen was outside the band
        self.settle_s = 0.0

    def update(self, t: np.ndarray, x: np.ndarray) -> None:
        m = (t >= self.t_step) & (t < self.t_end)
        if not m.any():
            return
        y = (x[m] - self.x0) / (self.x1 - self.x0)  # normalised: 0 before, 1 at target
        tt = t[m] - self.t_step
        self.peak = max(self.peak, float(y.max()))
        if self.pending:
            self.settle_s, self.pending = float(tt[0]), False
        outside = np.flatnonzero(np.abs(y - 1.0) > self.band)
        if outside.size:
            self.left_band = True
            if outside[-1] == y.size - 1:
                self.pending = True
            else:
                self.settle_s = float(tt[outside[-1] + 1])

    def result(self) -> dict:
        settle = None if self.pending else (self.settle_s * 1e3 if self.left_band else 0.0)
        overshoot = float(max(self.peak - 1.0, 0.0) * 100) if np.isfinite(self.peak) else 0.0
        return {"size_m": self.x1 - self.x0, "overshoot_pct": overshoot, "settling_ms": settle}


def step_metrics(t: np.ndarray, x: np.ndarray, t_step: float, t_end: float, x0: float, x1: float, band: float = 0.05) -> dict:
    """:class:`StepResponse` of whole arrays ``t`` (s) and ``x`` (m)."""
    step = StepResponse(t_step, t_end, x0, x1, band)
    step.update(t, x)
    return step.result()


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

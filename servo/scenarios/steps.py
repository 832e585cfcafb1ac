"""The ``steps`` scenario (``servo run``'s default): hold, reference steps, a sinusoidal
force disturbance, and the excitation current of ``scenario.excitation``."""
from __future__ import annotations

import numpy as np

from servo.errors import ConfigError
from servo.scenarios import excitation as excite
from servo.scenarios.base import Inputs, ScenarioKind

#: Most samples one period of a periodic excitation may hold (8 MB; a prbs's period,
#: rounded up to whole bits of its sequence, up to 4 times as many).
MAX_PERIOD_SAMPLES = 1 << 20


class ScenarioInputs(Inputs):
    """The ``servo run`` scenario of ``cfg.scenario``: hold, reference steps, then a
    sinusoidal force disturbance; and the excitation current of ``scenario.excitation``
    (:mod:`servo.scenarios.excitation`) from ``excitation_start`` on.  A periodic
    excitation (multisine, prbs) keeps one period; a chirp is evaluated in closed form."""

    def __init__(self, cfg):
        s = cfg.scenario
        self.dt = cfg.dt
        self.step_ticks = np.array([int(round(t / cfg.dt)) for t in s.step_times], dtype=np.int64)
        self.step_positions = np.array(s.step_positions, dtype=float)
        self.amplitude, self.hz, self.start_s = s.disturbance_amplitude, s.disturbance_hz, s.disturbance_start
        self.kind = s.excitation
        self.exc_start = int(round(s.excitation_start / cfg.dt))
        self.period = self._excitation_period(cfg) if self.kind in ("multisine", "prbs") else None
        if self.kind == "chirp":
            self.sweep_s = max((cfg.n_ticks - 1 - self.exc_start) * cfg.dt, cfg.dt)
            excite.chirp(2, cfg.dt, s.excitation_f_min, s.excitation_f_max, s.excitation_amplitude)  # checks them
        self.s = s

    @staticmethod
    def _excitation_period(cfg) -> np.ndarray:
        s, dt = cfg.scenario, cfg.dt
        n = int(round(s.excitation_period / dt))
        if n > MAX_PERIOD_SAMPLES:
            raise ConfigError(f"config: scenario.excitation_period = {s.excitation_period:g} s is {n} samples at "
                              f"{cfg.run.sample_rate_hz:g} Hz, more than {MAX_PERIOD_SAMPLES}; shorten it")  # fmt: skip
        if s.excitation == "multisine":
            try:
                return excite.multisine(n, dt, s.excitation_f_min, s.excitation_f_max, s.excitation_amplitude)
            except excite.ExcitationError as exc:
                raise ConfigError(f"config: scenario.excitation = multisine: {exc}") from None
        hold = max(1, int(excite.PRBS_BIT_HZ / (s.excitation_f_max * dt)))
        nbits = max(2, int(np.ceil(np.log2(n / hold + 1))))
        samples = excite.prbs_period(nbits, hold)
        if samples > 4 * MAX_PERIOD_SAMPLES:  # bits as long as the period (config refuses longer) make at most 3n
            raise ConfigError(f"config: scenario.excitation_f_max = {s.excitation_f_max:g} Hz makes a prbs period of "
                              f"{samples} samples, more than {4 * MAX_PERIOD_SAMPLES}; raise it")  # fmt: skip
        return excite.prbs(samples, dt, s.excitation_amplitude, nbits, hold)

    def excitation(self, ticks):
        """The excitation current (A) of ``scenario.excitation`` at ``ticks``."""
        ticks = np.asarray(ticks)
        if self.kind == "none":
            return np.zeros(ticks.shape)
        k = ticks - self.exc_start
        if self.kind == "chirp":
            from scipy.signal import chirp  # scipy.signal is 0.7 s of a run's start: only a chirp needs it

            s = self.s
            u = s.excitation_amplitude * chirp(k * self.dt, f0=s.excitation_f_min, t1=self.sweep_s,
                                                      f1=s.excitation_f_max, method="logarithmic")  # fmt: skip
        else:
            u = self.period[np.maximum(k, 0) % self.period.shape[0]]
        return np.where(k >= 0, u, 0.0)

    def reference(self, ticks):
        """Piecewise constant (m): ``step_positions[i]`` from ``step_times[i]`` on, 0 before."""
        ticks = np.asarray(ticks)
        # the last step at or before each tick (step times are non-decreasing: a later
        # step at the same tick wins, as it did when each step overwrote the ones before)
        levels = np.concatenate([[0.0], self.step_positions])
        return levels[np.searchsorted(self.step_ticks, ticks, side="right")]

    def disturbance(self, ticks):
        """``amplitude*sin(2*pi*hz*(t - start_s))`` from ``start_s`` on, 0 before (A)."""
        t = np.asarray(ticks) * self.dt
        if t.size and t.max() < self.start_s:  # not started in these ticks: no sine to evaluate
            return np.zeros(t.shape)
        d = self.amplitude * np.sin(2.0 * np.pi * self.hz * (t - self.start_s))
        d[t < self.start_s] = 0.0
        return d


class Steps(ScenarioKind):
    name = "steps"
    summary = "hold, reference steps, a sinusoidal force disturbance, an optional excitation"

    @classmethod
    def inputs(cls, cfg) -> Inputs:
        return ScenarioInputs(cfg)

    @classmethod
    def segments(cls, cfg) -> list[tuple[str, float, float]]:
        """Hold, each step, the disturbance."""
        s, end = cfg.scenario, cfg.run.duration_s
        marks = [(0.0, "hold")] + [(t, f"step {i + 1}") for i, t in enumerate(s.step_times)]
        if s.disturbance_amplitude > 0.0:
            marks.append((s.disturbance_start, "disturbance"))
        marks = sorted((t, name) for t, name in marks if t < end)
        return [(name, t0, (marks[i + 1][0] if i + 1 < len(marks) else end)) for i, (t0, name) in enumerate(marks)]

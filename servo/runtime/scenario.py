"""Scenario inputs of a run: reference, excitation and disturbance, as functions of the tick.

An :class:`Inputs` evaluates its three signals for any array of tick indices, so a run of
any length needs no array as long as the run: both the tick-by-tick path and the compiled
fast path read them through a :class:`Window` of :data:`BLOCK` ticks, refilled as the
run moves on.  A signal's value at a tick does not depend on which window computed it,
so both paths read the very same numbers.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from scipy import signal

from servo.config import Config
from servo.errors import ConfigError
from servo.runtime import excitation as excite

#: Ticks per input window (the same as the simulated drive's noise blocks).
BLOCK = 1024


class Inputs:
    """Per-tick inputs of a run.  Each method takes tick indices (int64, any shape) and
    returns the values (float64, same shape); ticks beyond the signal's end give 0.

    ``reference``: reference position relative to the holding position, m.
    ``excitation``: excitation current added to the controller's output, A.
    ``disturbance``: disturbance force on the arm (simulated drive only), A.
    """

    def reference(self, ticks: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(ticks))

    def excitation(self, ticks: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(ticks))

    def disturbance(self, ticks: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(ticks))

    @classmethod
    def zeros(cls) -> "Inputs":
        """No reference change, no excitation, no disturbance."""
        return cls()


class ArrayInputs(Inputs):
    """Inputs given as arrays, one value per tick from tick 0 (each (n,), any length)."""

    def __init__(self, r=None, u_exc=None, d=None):
        self.r, self.u_exc, self.d = (np.zeros(0) if a is None else np.ascontiguousarray(a, dtype=float)
                                      for a in (r, u_exc, d))  # fmt: skip

    @staticmethod
    def _at(a: np.ndarray, ticks: np.ndarray) -> np.ndarray:
        ticks = np.asarray(ticks)
        inside = ticks < a.shape[0]
        return np.where(inside, a[np.where(inside, ticks, 0)] if a.shape[0] else 0.0, 0.0)

    def reference(self, ticks):
        return self._at(self.r, ticks)

    def excitation(self, ticks):
        return self._at(self.u_exc, ticks)

    def disturbance(self, ticks):
        return self._at(self.d, ticks)


#: Most samples one period of a periodic excitation may hold (8 MB).
MAX_PERIOD_SAMPLES = 1 << 20


class ScenarioInputs(Inputs):
    """The ``servo run`` scenario of ``cfg.scenario``: hold, reference steps, then a
    sinusoidal force disturbance; and the excitation current of ``scenario.excitation``
    (:mod:`servo.runtime.excitation`) from ``excitation_start`` on.  A periodic
    excitation (multisine, prbs) keeps one period; a chirp is evaluated in closed form."""

    def __init__(self, cfg: Config):
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
    def _excitation_period(cfg: Config) -> np.ndarray:
        s, dt = cfg.scenario, cfg.dt
        n = int(round(s.excitation_period / dt))
        if n > MAX_PERIOD_SAMPLES:
            raise ConfigError(f"config: scenario.excitation_period = {s.excitation_period:g} s is {n} samples at "
                              f"{cfg.run.sample_rate_hz:g} Hz, more than {MAX_PERIOD_SAMPLES}; shorten it")  # fmt: skip
        if s.excitation == "multisine":
            return excite.multisine(n, dt, s.excitation_f_min, s.excitation_f_max, s.excitation_amplitude)
        hold = max(1, int(0.44 / (s.excitation_f_max * dt)))
        nbits = max(2, int(np.ceil(np.log2(n / hold + 1))))
        return excite.prbs(excite.prbs_period(nbits, hold), dt, s.excitation_amplitude, nbits, hold)

    def excitation(self, ticks):
        """The excitation current (A) of ``scenario.excitation`` at ``ticks``."""
        ticks = np.asarray(ticks)
        if self.kind == "none":
            return np.zeros(ticks.shape)
        k = ticks - self.exc_start
        if self.kind == "chirp":
            s = self.s
            u = s.excitation_amplitude * signal.chirp(k * self.dt, f0=s.excitation_f_min, t1=self.sweep_s,
                                                      f1=s.excitation_f_max, method="logarithmic")  # fmt: skip
        else:
            u = self.period[np.maximum(k, 0) % self.period.shape[0]]
        return np.where(k >= 0, u, 0.0)

    def reference(self, ticks):
        """Piecewise constant (m): ``step_positions[i]`` from ``step_times[i]`` on, 0 before."""
        ticks = np.asarray(ticks)
        r = np.zeros(ticks.shape)
        for k, pos in zip(self.step_ticks, self.step_positions):
            r[ticks >= k] = pos
        return r

    def disturbance(self, ticks):
        """``amplitude*sin(2*pi*hz*(t - start_s))`` from ``start_s`` on, 0 before (A)."""
        t = np.asarray(ticks) * self.dt
        d = self.amplitude * np.sin(2.0 * np.pi * self.hz * (t - self.start_s))
        d[t < self.start_s] = 0.0
        return d


def scenario_inputs(cfg: Config) -> Inputs:
    """The inputs of ``servo run``'s scenario: :class:`ScenarioInputs`, or the HDD
    benchmark's runout and force disturbance (:class:`servo.hdd.BenchmarkInputs`)."""
    if cfg.scenario.kind == "hdd_benchmark":
        from servo.hdd.disturbances import BenchmarkInputs, generate  # it builds on this module

        try:
            dist = generate(cfg.n_ticks, cfg.scenario.hdd_version, seed=cfg.run.seed, fs=cfg.run.sample_rate_hz)
        except ValueError as exc:
            raise ConfigError(f"config: scenario.kind = hdd_benchmark: {exc}") from None
        return BenchmarkInputs(dist)
    return ScenarioInputs(cfg)


class Window:
    """One signal of an :class:`Inputs` over an aligned block of :data:`BLOCK` ticks,
    sample-and-held every ``hold`` ticks (value at tick k = ``signal(k - k % hold)``).

    ``load(k)`` makes the block holding tick ``k`` current and returns k's index in
    :attr:`values`.  A refill (one vectorised call, a few us) happens once per block.
    """

    def __init__(self, signal: Callable[[np.ndarray], np.ndarray], hold: int = 1, size: int = BLOCK):
        self.signal = signal
        self.hold = int(hold)
        self.size = int(size)
        self.values = np.zeros(self.size)
        self.base = -1

    def load(self, k: int) -> int:
        base = k - k % self.size
        if base != self.base:
            ticks = np.arange(base, base + self.size, dtype=np.int64)
            self.values[:] = self.signal(ticks - ticks % self.hold)
            self.base = base
        return k - base

    def at(self, k: int) -> float:
        """The value at tick ``k``."""
        return float(self.values[self.load(k)])


def segments(cfg: Config) -> list[tuple[str, float, float]]:
    """Named time segments of the scenario: hold, each step, the disturbance (the HDD
    benchmark's: the first 10 ms it ignores, then track following)."""
    s, end = cfg.scenario, cfg.run.duration_s
    if s.kind == "hdd_benchmark":
        return [(name, a, b) for name, a, b in (("settling", 0.0, min(0.01, end)), ("track following", 0.01, end)) if a < end]
    marks = [(0.0, "hold")] + [(t, f"step {i + 1}") for i, t in enumerate(s.step_times)]
    if s.disturbance_amplitude > 0.0:
        marks.append((s.disturbance_start, "disturbance"))
    marks = sorted((t, name) for t, name in marks if t < end)
    return [(name, t0, (marks[i + 1][0] if i + 1 < len(marks) else end)) for i, (t0, name) in enumerate(marks)]

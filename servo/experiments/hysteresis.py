"""The hysteresis-loop experiments (paper section IV-A, Fig. 2-4) on the simulated drive.

* Small loop (Fig. 2-3): an amplitude-modulated sine current (carrier ``hz``, envelope
  ``sin(pi*t/T)`` rising from zero to ``amplitude`` and back) added to the PI holding
  loop's output, compensator off.  The current-vs-position record shows the nested loops
  of the pivot; :func:`servo.identify.dahl_fit.fit_dahl` fits eq. (6-7) to it.
  Default 6 mA at 5 Hz for 2 s: the arm moves +-3.7 um, a bit over one Dahl length
  (``Ha/sigma`` = 3.1 um) each way, so the loops go from the elastic start (slope
  ``sigma``) to 80 % of the sliding level ``Ha`` and both parameters are seen; at 5 Hz
  the inertial force is 0.5 % of ``Ha`` (neglected by the fit).
* Large loop (Fig. 4): the holding loop tracks a slow triangle reference (+-5 mm at
  0.5 Hz, 20 mm/s): the arm slides all the time but at the turnarounds, the current
  traces a parallelogram of height ``2*Ha`` whose average slope is the bearing stiffness
  of eq. (11); :func:`average_slope` fits ``u = J*x'' + Fc*sgn(x') + K*x + h0`` to it.  A triangle
  (constant speed) rather than a sine keeps the inertial force out of the slope.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servo.config import Config
from servo.runtime.closedloop import simulate, simulation_ticks
from servo.identify.least_squares import LSResult, least_squares
from servo.identify.regressors import paper_regression


@dataclass(frozen=True)
class HysteresisExperiment:
    """Small loop: AM sine ``amplitude`` (A), carrier ``hz``, ``duration_s``.  Large loop:
    triangle reference ``large_amplitude_m`` (m), ``large_hz``, ``large_cycles``."""

    amplitude: float = 6e-3
    hz: float = 5.0
    duration_s: float = 2.0
    large_amplitude_m: float = 5e-3
    large_hz: float = 0.5
    large_cycles: float = 2.0


def am_sine(n: int, dt: float, amplitude: float, hz: float) -> np.ndarray:
    """Amplitude-modulated sine (A): ``amplitude*sin(pi*t/T)*sin(2*pi*hz*t)`` over ``T = n*dt``."""
    t = np.arange(n) * dt
    return amplitude * np.sin(np.pi * t / (n * dt)) * np.sin(2 * np.pi * hz * t)


def triangle(n: int, dt: float, amplitude: float, hz: float) -> np.ndarray:
    """Triangle wave (m) starting at 0 going up, peak ``amplitude``."""
    ph = (np.arange(n) * dt * hz + 0.25) % 1.0
    return amplitude * (4 * np.abs(ph - 0.5) - 1.0) * -1.0


def run_small_loop(cfg: Config, exp: HysteresisExperiment = HysteresisExperiment()) -> dict:
    """Simulate the AM-sine experiment (compensator off); returns the log columns."""
    n = simulation_ticks(exp.duration_s, cfg.dt, "the AM sine's duration")
    return simulate(cfg, am_sine(n, cfg.dt, exp.amplitude, exp.hz), compensation=False)


def run_large_loop(cfg: Config, exp: HysteresisExperiment = HysteresisExperiment()) -> dict:
    """Simulate the large-range experiment (triangle reference, compensator off)."""
    n = simulation_ticks(exp.large_cycles / exp.large_hz, cfg.dt, "the large loop's duration (large_cycles / large_hz)")
    r = triangle(n, cfg.dt, exp.large_amplitude_m, exp.large_hz)
    return simulate(cfg, np.zeros(n), r=r, compensation=False)


def average_slope(t, x, v, u, dt: float) -> LSResult:
    """Eq. (11): least squares of ``u = J*x'' + Fc*sgn(x') + K*x + h0`` over a large loop
    (the paper's derivative path: measured velocity, backward-difference acceleration).
    ``K`` is the average slope (A/m), ``Fc`` half the loop's height (A).  The inertial
    term is there for the turnarounds, where the holding loop reverses the arm in a few
    ms and ``J*x''`` (mA) would otherwise tilt the slope; at constant speed ``B*x'`` is
    ``Fc*sgn(x')`` in disguise, so ``B`` is left out (it ends up in ``Fc``)."""
    return least_squares(paper_regression(t, x, u, v, dt, terms=("J", "Fc", "K", "h0")))


__all__ = ["HysteresisExperiment", "am_sine", "average_slope", "run_large_loop", "run_small_loop", "triangle"]

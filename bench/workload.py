"""What the benchmarks feed the kernels: the default config's records and input tables.

Inputs are a motion that exercises every branch of the controller: a position sine whose
amplitude sweeps from 0.2 um (inside the pivot's pre-sliding regime: Dahl estimate,
SLOW) to 30 um (sliding: FAST, eq. 3) and back, with sensor-like noise, so that
turnarounds, regime switches and the integrator all happen.  Tables have
:data:`bench.loops.M` rows and whole sine cycles; every benchmark reads them cyclically.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench.loops import M
from kernels.compensator import direction
from servo.config import Config
from servo.runtime.controller import Controller
from servo.runtime.simplant import SimPlant, build_plant


def config() -> Config:
    """The config the budgets are set against: the built-in default (50 kHz)."""
    return Config()


@dataclass
class Motion:
    """Per-row motion (each shape (M,)): position x (m), velocity v (m/s), direction s."""

    x: np.ndarray
    v: np.ndarray
    s: np.ndarray


def _envelope(lo: float, hi: float) -> np.ndarray:
    """Log sweep lo -> hi -> lo over the table (periodic: the table wraps smoothly)."""
    tri = 1.0 - np.abs(2.0 * np.arange(M) / M - 1.0)
    return lo * (hi / lo) ** tri


def _carrier() -> np.ndarray:
    """Phase of a sine with :data:`CYCLES` whole cycles over the table (rad)."""
    return 2.0 * math.pi * CYCLES * np.arange(M) / M


#: Sine cycles per table: 16 cycles in 4096 samples, 195 Hz at 50 kHz.
CYCLES = 16


def motion(cfg: Config, seed: int = 7) -> Motion:
    """A position sine (16 cycles over the table, ~195 Hz at 50 kHz) whose amplitude
    sweeps 0.2 um -> 30 um -> 0.2 um, plus 1 nm / 1 um/s noise; direction with the
    controller's deadband."""
    rng = np.random.default_rng(seed)
    amp = _envelope(0.2e-6, 30e-6)
    w = 2.0 * math.pi * CYCLES / (M * cfg.dt)
    ph = _carrier()
    x = amp * np.sin(ph) + 1e-9 * rng.standard_normal(M)
    v = amp * w * np.cos(ph) + 1e-6 * rng.standard_normal(M)
    s = np.empty(M)
    prev = 1.0
    for i in range(M):
        prev = direction(prev, v[i], cfg.controller.direction_deadband)
        s[i] = prev
    return Motion(x, v, s)


#: The ``[compensator]`` section with every term of :mod:`kernels.cancel` on, sized
#: against the motion of :func:`motion` (+-30 um at most) so that every branch is taken:
#: the periodic term's period is 2 um (the large cycles sweep 30 of them), kf(x) is
#: referred to a 30 um stroke so that it leaves ``1 +- kf_authority`` near both ends of the
#: large cycles, and the authority (2.5 mA) holds |u_c| on the samples where the paper's
#: terms, the Coulomb term and the periodic force add up beyond it.
EVERY_TERM = dict(
    b_asymmetry=0.2, coulomb_extra=1e-3, coulomb_static=1.5e-3, stribeck_velocity=2e-3, coulomb_asymmetry=0.1,
    periodic_amplitudes=[1e-4, 5e-5, 2e-5, 1e-5], periodic_phases=[0.3, -1.0, 2.0, 0.5], periodic_period=2e-6,
    kf_linear=0.9, kf_quadratic=0.5, kf_stroke=30e-6, kf_authority=0.3, authority=2.5e-3,
)


def controller(cfg: Config, compensation: bool = True) -> Controller:
    """A controller that has taken over at rest at x = 0 with the holding current."""
    ctl = Controller(cfg, compensation)
    ctl.start(0.0, 0.0, build_plant(cfg.drive, cfg.dt).u_hold)
    return ctl


def controller_inputs(cfg: Config, seed: int = 7) -> np.ndarray:
    """Rows ``(x, v_meas, r, u_exc)`` for the controller tick: the motion, reference 0."""
    m = motion(cfg, seed)
    return np.ascontiguousarray(np.column_stack([m.x, m.v, np.zeros(M), np.zeros(M)]))


def plant(cfg: Config) -> SimPlant:
    return build_plant(cfg.drive, cfg.dt)


def plant_inputs(cfg: Config, seed: int = 7) -> np.ndarray:
    """Rows ``(u, d)``: the holding current plus a sine (16 cycles over the table) of
    2 mA -> 60 mA -> 2 mA (arm motion from inside the pre-sliding regime to tens of um),
    no disturbance."""
    rng = np.random.default_rng(seed)
    u = plant(cfg).u_hold + _envelope(2e-3, 60e-3) * np.sin(_carrier()) + 1e-5 * rng.standard_normal(M)
    return np.ascontiguousarray(np.column_stack([u, np.zeros(M)]))


def noise(seed: int = 7) -> np.ndarray:
    """Rows ``(nx, nv)`` of standard normals (the sensor's noise draws)."""
    return np.random.default_rng(seed).standard_normal((M, 2))


def closed_loop_inputs(cfg: Config) -> np.ndarray:
    """Rows ``(r, u_exc, d)``: reference steps of +-0.3 um and +-20 um, a 1 mA 40 Hz
    disturbance force, over the table (82 ms at 50 kHz)."""
    k = np.arange(M)
    r = np.where(k < M // 4, 0.3e-6, np.where(k < M // 2, 0.0, np.where(k < 3 * M // 4, 20e-6, 0.0)))
    d = 1e-3 * np.sin(2.0 * math.pi * 40.0 * k * cfg.dt)
    return np.ascontiguousarray(np.column_stack([r, np.zeros(M), d]))

"""The friction-identification experiment (paper section IV-B, Fig. 5) on the simulated drive.

The paper applies a 6 kHz, 1 V p-p square wave and sees sub-micron motion.  On the default
drive that would stay inside the pivot's pre-sliding regime (the Dahl length ``Ha/sigma``
is 3.1 um), where the pivot is a spring and model (3) does not hold.  The default here is
a 20 mA, 25 Hz square wave under a 5 Hz holding loop:

* the arm slides about 5.5 mm peak to peak, ~1800 Dahl lengths, so the pivot is in the
  sliding regime 95 % of the time (model 3's regime), while staying well inside the
  +-15 mm stroke and the 1 A limit;
* the bias ``K*x`` reaches +-0.27 mA, a quarter of the friction level, so ``K`` is
  excited; the inertial force (20 mA) dominates, so ``J`` is well determined;
* 25 half-periods per second give 50 velocity reversals for ``Fc``;
* the 5 Hz holding loop only stops the drift (the offset ``h0``) and leaves the 25 Hz
  motion free.

The recording (``t``, ``u`` the total VCM current, ``x``, ``v`` the LDV-like measured
position and velocity) is what a lab would record; :func:`representable` gives what model
(3) can represent of the simulated drive: the drive's ``J, B, K, h0`` plus the least-
squares projection of its Dahl pivot force onto the regressor (the pivot is not a Coulomb
element near the reversals, so its best ``Fc`` is below ``Ha`` and part of it shows up
in ``B`` and ``K``).  The projection depends on how the rows are filtered, so it is
computed per derivative path.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servo.config import Config
from servo.experiments.holding import holding_gains
from servo.runtime.closedloop import simulate, simulation_ticks
from servo.identify.least_squares import least_squares
from servo.identify.regressors import TERMS, RobustSettings, paper_regression, robust_regression
from servo.io.recording import Recording


@dataclass(frozen=True)
class SquareWave:
    """Square-wave excitation: ``amplitude`` (A), ``hz``, ``duration_s``, and the holding
    loop bandwidth ``holding_hz`` (Hz)."""

    amplitude: float = 0.02
    hz: float = 25.0
    duration_s: float = 1.0
    holding_hz: float = 5.0


def square_wave(n: int, dt: float, amplitude: float, hz: float) -> np.ndarray:
    """``+-amplitude`` square wave starting high, ``n`` samples every ``dt`` s."""
    phase = (np.arange(n) * dt * hz) % 1.0
    return np.where(phase < 0.5, amplitude, -amplitude)


def run_square_wave(cfg: Config, sw: SquareWave = SquareWave()) -> tuple[Recording, dict]:
    """Simulate the experiment (compensator off).  Returns the recording and the log."""
    c = cfg.replace(controller={"kind": "pi", "pi": holding_gains(cfg.drive.J, sw.holding_hz)})
    n = simulation_ticks(sw.duration_s, c.dt, "the square wave's duration")
    log = simulate(c, square_wave(n, c.dt, sw.amplitude, sw.hz), compensation=False)
    rec = Recording(log["t"], log["u"], log["x"], log["v"] if cfg.drive.measures_velocity else None,
                    source="simulated square wave", meta={"experiment": "square_wave", **sw.__dict__})  # fmt: skip
    return rec, log


def representable(cfg: Config, log: dict, path: str, settings: RobustSettings | None = None) -> dict[str, float]:
    """Parameters of model (3) that best represent the simulated drive on this motion, as
    seen through derivative ``path``: the drive's ``J``, ``B``, ``Fc`` (its Coulomb term),
    ``K``, ``h0`` plus the least-squares fit of eq. (4), built the same way, to the pivot's
    Dahl force alone (the force the controller's estimator tracks with the drive's own
    Dahl parameters, ``h_hat``).  The difference between an estimate and this is the
    estimator's error; between this and the drive's values, model (3)'s."""
    d = cfg.drive
    t, x, H = log["t"], log["x"], log["h_hat"]
    if path == "paper":
        reg = paper_regression(t, x, H, log["v"], cfg.dt, TERMS)
    else:
        reg = robust_regression(t, x, H, cfg.dt, TERMS, settings)
    proj = least_squares(reg, check=False).params
    own = np.array([d.J, d.B, d.Fc, d.K, d.h0])
    return {k: float(p) for k, p in zip(TERMS, own + proj)}


def force_lag(cfg: Config) -> dict[str, float]:
    """How late the recorded command acts on the simulated arm, per derivative path (s):
    the drive's input delay and the link latency; the robust path adds the half sample of
    the zero-order hold (the paper path's rows already pair each interval with its held
    command)."""
    delay = cfg.drive.input_delay_s + cfg.link.loop_latency_ticks * cfg.dt
    return {"paper": delay, "robust": delay + 0.5 * cfg.dt}


def nominal(cfg: Config) -> dict[str, float]:
    """The drive's own values: ``Fc`` is its sliding friction, the Dahl asymptote plus any
    Coulomb term."""
    d = cfg.drive
    return {"J": d.J, "B": d.B, "Fc": d.Ha + d.Fc, "K": d.K, "h0": d.h0}


__all__ = ["SquareWave", "force_lag", "nominal", "representable", "run_square_wave", "square_wave"]

"""What a compensator would have removed from a recording's force residual.

A compensator cancels the forces of its model from the measured motion as it happens:
``u_c`` from the stage's own signals (causal velocity estimate, deadbanded direction, the
Dahl state with its turnaround memory, the authority), not from the zero-phase filtered
motion a diagnosis fits on.  Run over a recording's positions, the stage gives the
``u_c`` it would have commanded; what is left of the force once it is taken away,

    e = rows(u - u_c) - J*rows(x'')

is what the compensated drive would still have to be pushed by beyond the double
integrator of eq. (10): the residual a compensator leaves.  The rows are the diagnosis'
inverse-dynamics rows (:func:`servo.diagnose.signals.make_signals`: the force and
``u_c`` filtered like the position, parallel-decimated), and the error is relative to the
force on the held-out part (the last ``test_fraction`` of the rows, usable rows only),
as the diagnosis reports it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servo.config import Config
from servo.diagnose.signals import make_signals
from servo.io.recording import Recording
from servo.runtime.controller import Controller

#: the compensator fields of each term beyond eq. (9), and their "off" values (the
#: Coulomb level itself is eq. 9's, whichever element carries it)
BEYOND_EQ9 = {
    "asymmetric viscous friction": {"b_asymmetry": 0.0},
    "Stribeck rise and Coulomb asymmetry": {"coulomb_static": 0.0, "coulomb_asymmetry": 0.0},
    "force periodic in position": {"periodic_amplitudes": [], "periodic_phases": []},
    "position-dependent force constant": {"kf_linear": 0.0, "kf_quadratic": 0.0},
}


def compensation_current(cfg: Config, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
    """``u_c`` (n,) the stage of ``cfg`` commands along measured positions ``x`` (m, one
    per tick of ``cfg.dt``) and velocities ``v`` (m/s; None: estimated as the stage
    does).  The controller's output does not enter ``u_c``."""
    ctl = Controller(cfg, compensation=True)
    n = x.shape[0]
    out = np.empty(n)
    vm = np.full(n, math.nan) if v is None else np.asarray(v, dtype=float)
    ctl.start(float(x[0]), float(vm[0]), 0.0)
    for k in range(n):
        ctl.tick(float(x[k]), float(vm[k]), 0.0, 0.0)
        out[k] = ctl.stage_state[0]["u_c"]
    return out


@dataclass
class Residual:
    """Held-out force residual (% of the force) with no compensator (``J*x''`` alone),
    per compensator (name -> %), and ``rows`` the usable held-out rows it is taken on."""

    none_pct: float
    pct: dict
    rows: int
    J: float


def compensated_residual(rec: Recording, configs: dict, J: float, test_fraction: float = 0.25) -> Residual:
    """The held-out residual ``e`` (module doc) of ``rec`` (force in the compensators'
    unit) under each config of ``configs`` (name -> :class:`Config`, its compensator at
    the recording's rate), for the inertia ``J`` (force*s^2/m)."""
    sig = make_signals(rec)
    m = sig.m
    test = np.zeros(m, bool)
    test[int(round(m * (1.0 - test_fraction))) :] = True
    test &= sig.valid
    ja = J * sig.rows(sig.af)
    y = sig.force_rows()
    scale = float(np.linalg.norm(y[test]))

    def pct(e):
        return 100.0 * float(np.linalg.norm(e[test])) / scale

    out = {}
    for name, cfg in configs.items():
        uc = compensation_current(cfg, rec.x, rec.v)
        out[name] = pct(sig.force_rows(rec.u - uc) - ja)
    return Residual(pct(y - ja), out, int(test.sum()), J)


def at_rate(cfg: Config, rec: Recording) -> Config:
    """``cfg`` at the recording's sample rate, its velocity estimator's cutoff below
    Nyquist (at most its own, at most a fifth of the rate); the simulated drive's modes,
    which the stage does not use, are dropped (they may lie above the new Nyquist)."""
    fs = 1.0 / rec.dt
    cut = min(cfg.controller.velocity_cutoff_hz, fs / 5.0)
    return cfg.replace(run={"sample_rate_hz": fs}, controller={"velocity_cutoff_hz": cut},
                       drive={"mode_hz": [], "mode_zeta": [], "mode_gain": []})  # fmt: skip


__all__ = ["BEYOND_EQ9", "Residual", "at_rate", "compensated_residual", "compensation_current"]

"""The PI holding loop with rate feedback: the paper's experiments' controller (Fig. 2, 6).

    u_n = kp*e_p + I - kd*v + u_exc,      I += ki*dt*e   (unless winding up)

clamped to the holding limit and to the room the stage leaves under the current limit
(:func:`kernels.holding.holding_pi`); ``e = r_base + r - x``, ``e_p = r_base + b*r - x``
(setpoint weight ``b``).  The default gains place the loop at 100 Hz on the compensated
plant ``J*x'' = u_n``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import float64, from_dtype, void

from kernels._cache import kernel
from kernels.holding import holding_pi, holding_pi_bumpless
from servo.fields import P
from servo.controllers.base import ControllerKind

PARAMS = np.dtype(
    [
        ("dt", "f8"),  # sample period, s
        ("kp", "f8"),  # proportional gain, A/m
        ("ki", "f8"),  # integral gain, A/(m*s)
        ("kd", "f8"),  # rate feedback, A*s/m
        ("b", "f8"),  # setpoint weight of the proportional term
        ("u_n_max", "f8"),  # output limit, A
    ]
)
STATE = np.dtype([("integ", "f8")])  # integrator, A
_c_t, _p_t = from_dtype(STATE), from_dtype(PARAMS)  # the records (kernels.compose)


@kernel(void(_c_t, _p_t, float64, float64, float64), helper=True)
def pi_start(c, p, x, v, u_n):
    """Bumpless take-over: the integrator that makes the first output ``u_n`` (A)."""
    c.integ = holding_pi_bumpless(u_n, 0.0, v, p.kp, p.kd)


@kernel(float64(_c_t, _p_t, float64, float64, float64, float64, float64, float64, float64), helper=True)
def pi_tick(c, p, x, v, r_base, r, u_exc, lo, hi):
    """One sample; returns ``u_n`` (A)."""
    e = (r_base + r) - x
    e_p = (r_base + p.b * r) - x
    u_n, c.integ = holding_pi(e, e_p, v, c.integ, u_exc, p.kp, p.ki, p.kd, p.dt,
                              max(-p.u_n_max, lo), min(p.u_n_max, hi))  # fmt: skip
    return u_n


@kernel(void(float64[::1], _c_t), helper=True)
def pi_log(out, c):
    """No columns of its own."""


@dataclass
class PISection:
    """The PI holding loop with rate feedback (kind "pi").  The default gains place the loop
    at 100 Hz on the compensated plant J*x'' = u_n (damping 0.7); the 7 kHz flexible mode
    leaves an upper gain margin of 4.26 dB (the loop goes unstable at 1.63x these gains)."""

    kp: float = P(394.8, "A/m", "proportional gain (J*w^2, w = 2*pi*100 Hz)", 0.0)
    ki: float = P(4.961e4, "A/(m*s)", "integral gain (J*w^3/5)", 0.0)
    kd: float = P(0.8796, "A*s/m", "rate feedback gain (2*0.7*J*w)", 0.0)
    setpoint_weight: float = P(0.6, "-", "weight of the reference in the proportional term (2-DOF PID)", 0.0, 1.0)
    holding_limit: float = P(1.0, "A", "output limit of the loop", 0.0, None, lo_open=True)


class PI(ControllerKind):
    name = "pi"
    summary = "PI holding loop with rate feedback and setpoint weighting (the paper's experiments)"
    Section = PISection
    STATE, PARAMS = STATE, PARAMS
    start, tick, log = staticmethod(pi_start), staticmethod(pi_tick), staticmethod(pi_log)

    @classmethod
    def params(cls, s: PISection, cfg) -> np.ndarray:
        p = np.zeros(1, PARAMS)
        for name, v in dict(dt=cfg.dt, kp=s.kp, ki=s.ki, kd=s.kd, b=s.setpoint_weight, u_n_max=s.holding_limit).items():
            p[name] = v
        return p

    @classmethod
    def response(cls, s: PISection, cfg, f_hz) -> np.ndarray:
        """``kp + ki*dt*z^-1/(1 - z^-1) + kd*V/X``: the integrator as implemented, the rate
        term through the velocity the stage uses (the drive's, ``j*w``, when it measures
        one and ``velocity_source = "auto"``; else the filtered backward difference)."""
        dt = cfg.dt
        w = 2 * np.pi * np.asarray(f_hz, float)
        zi = np.exp(-1j * w * dt)  # z^-1
        c = cfg.controller
        if c.velocity_source == "auto" and cfg.drive.measures_velocity:
            rate = 1j * w
        else:
            a = np.exp(-2 * np.pi * c.velocity_cutoff_hz * dt)
            rate = (1 - a) * (1 - zi) / dt / (1 - a * zi)
        return s.kp + s.ki * dt * zi / (1 - zi) + s.kd * rate

    @classmethod
    def to_control(cls, s: PISection, cfg):
        """``kp + ki*dt/(z - 1) + kd*D(z)``: :meth:`response` exactly when the rate comes
        from the estimator (``D = (1 - a)(z - 1)/(dt (z - a))``); a measured velocity
        (``j*w``, not a function of ``z``) is read as the backward difference
        ``(z - 1)/(dt z)``, whose phase lags it by ``w*dt/2`` (0.5 deg at 150 Hz, 50 kHz)."""
        import control

        dt = cfg.dt
        z = control.tf([1.0, 0.0], [1.0], dt)
        c = cfg.controller
        if c.velocity_source == "auto" and cfg.drive.measures_velocity:
            rate = (z - 1) / (dt * z)
        else:
            a = np.exp(-2 * np.pi * c.velocity_cutoff_hz * dt)
            rate = (1 - a) * (z - 1) / (dt * (z - a))
        return control.minreal(s.kp + s.ki * dt / (z - 1) + s.kd * rate, verbose=False)

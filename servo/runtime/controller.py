"""The controller a run steps every tick: PI holding loop plus the paper's compensator.

A thin owner of the :data:`~kernels.controller.CTRL_STATE` / ``CTRL_PARAMS`` records; the
arithmetic is in :mod:`kernels.controller`.
"""
from __future__ import annotations

import math

import numpy as np

from kernels.controller import CTRL_PARAMS, CTRL_STATE, controller_start, controller_tick
from servo.config import Config


def controller_params(cfg: Config, compensation: bool | None = None) -> np.ndarray:
    """The :data:`~kernels.controller.CTRL_PARAMS` record of ``cfg``; ``compensation``
    overrides ``cfg.compensator.enabled`` when given."""
    c, k = cfg.controller, cfg.compensator
    on = k.enabled if compensation is None else compensation
    p = np.zeros(1, CTRL_PARAMS)
    values = dict(
        dt=cfg.dt, kp=c.kp, ki=c.ki, kd=c.kd, b=c.setpoint_weight, u_n_max=c.holding_limit, u_max=c.current_limit,
        use_measured_v=1.0 if c.velocity_source == "auto" else 0.0,
        v_alpha=math.exp(-2.0 * math.pi * c.velocity_cutoff_hz * cfg.dt),
        v_deadband=c.direction_deadband, comp_on=1.0 if on else 0.0,
        B=k.B, Fc=k.Fc, K=k.K, h0=k.h0, sigma=k.sigma, Ha=k.Ha, alpha=k.alpha,
        v_on=k.fast_on_speed, v_off=k.fast_off_speed, xi_on=k.fast_on_distance,
    )  # fmt: skip
    for name, v in values.items():
        p[name] = v
    return p


class Controller:
    """State and parameters of one controller; :meth:`start` then :meth:`tick` per sample."""

    def __init__(self, cfg: Config, compensation: bool | None = None):
        self.params = controller_params(cfg, compensation)
        self.state = np.zeros(1, CTRL_STATE)

    def warm_up(self) -> None:
        """Call the kernels once on scratch copies, so that the first tick of a run pays
        no first-call cost (the first dispatch on these record types takes ~0.2 ms)."""
        state, params = self.state.copy(), self.params.copy()
        controller_start(state, params, 0.0, 0.0, 0.0)
        controller_tick(state, params, 0.0, 0.0, 0.0, 0.0)

    def start(self, x: float, v: float, u_now: float) -> None:
        """Take over bumplessly at position ``x`` (m), velocity ``v`` (m/s, NaN if not
        measured) with ``u_now`` (A) applied."""
        controller_start(self.state, self.params, x, v, u_now)

    def tick(self, x: float, v: float, r: float, u_exc: float) -> float:
        """One sample; returns the current command (A).  See
        :func:`kernels.controller.controller_tick`."""
        return controller_tick(self.state, self.params, x, v, r, u_exc)

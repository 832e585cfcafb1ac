"""The controller a run steps every tick: the configured kind on the compensator stage.

``[controller] kind`` picks a registered kind (:mod:`servo.controllers`); it sits on the
stage of :mod:`kernels.stage` (motion signals, the paper's compensator, the current
limit).  This class owns the four records (stage and kind, state and parameters) and the
kind's composed kernels (:mod:`kernels.compose`); the arithmetic is in the kernels.
"""
from __future__ import annotations

import math

import numpy as np

from kernels._cache import entry_point
from kernels.compose import LOG_COLUMNS, LOG_UNITS
from kernels.stage import STAGE_PARAMS
from servo import physics
from servo.config import Config
from servo.controllers import get_kind
from servo.errors import ConfigError


def stage_params(cfg: Config, compensation: bool | None = None) -> np.ndarray:
    """The :data:`~kernels.stage.STAGE_PARAMS` record of ``cfg``; ``compensation``
    overrides ``cfg.compensator.enabled`` when given."""
    c, k = cfg.controller, cfg.compensator
    on = k.enabled if compensation is None else compensation
    p = np.zeros(1, STAGE_PARAMS)
    values = dict(
        dt=cfg.dt, u_max=c.current_limit,
        use_measured_v=1.0 if c.velocity_source == "auto" else 0.0,
        v_alpha=math.exp(-2.0 * math.pi * c.velocity_cutoff_hz * cfg.dt),
        v_deadband=c.direction_deadband, comp_on=1.0 if on else 0.0,
        v_on=k.fast_on_speed, v_off=k.fast_off_speed, xi_on=k.fast_on_distance,
        uc_max=k.authority if k.authority > 0 else math.inf,
    )  # fmt: skip
    physics.fill(p, {**values, **physics.stage_values(k)})  # each effect's compensator term
    return p


#: What ``--compensation``/``--compensator`` may ask for: the compensator settings to run.
COMPENSATION_CHOICES = {"on": (True,), "off": (False,), "compare": (True, False), "both": (True, False)}


def compensation_runs(cfg: Config, requested: str | None = None) -> tuple[bool, ...]:
    """The compensator settings a command runs (True: with the compensator), in order.

    ``requested`` (``on``, ``off``, ``compare``/``both``) comes from the command line;
    None follows ``[compensator] enabled``: with and without the compensator to compare
    when it is enabled, without it when not.  Asking for the compensator that the
    config turns off is a :class:`ConfigError` (one line), not a silent override."""
    if requested is None:
        return COMPENSATION_CHOICES["compare"] if cfg.compensator.enabled else (False,)
    runs = COMPENSATION_CHOICES[requested]
    if True in runs and not cfg.compensator.enabled:
        raise ConfigError(f"the compensator is asked for ({requested}) but [compensator] enabled = false turns it off: "
                          "set compensator.enabled = true, or ask for off")  # fmt: skip
    return runs

#: The entry points of a kind's tick and log row, checked by :meth:`Controller.warm_up`
#: once per process (keyed by the kind's compiled tick).
_WARM: dict = {}


class Controller:
    """State and parameters of the configured controller on its stage; :meth:`start`,
    then :meth:`tick` once per sample.

    ``buf``: the four records in one array (what the kernels take); ``stage_state``/
    ``stage_params``: the stage's records, ``state``/``params``: the kind's (views into
    ``buf``); ``kernels``: the kind's composed kernels; ``log_columns``/``log_units``: the
    columns of a run log of this controller (the common ones, then the kind's).
    """

    def __init__(self, cfg: Config, compensation: bool | None = None):
        self.kind = get_kind(cfg.controller.kind)
        self.kernels = self.kind.kernels()
        self.buf = np.zeros(1, self.kernels.dtype)
        self.stage_state, self.stage_params = self.buf["stage_state"], self.buf["stage_params"]
        self.state, self.params = self.buf["state"], self.buf["params"]
        self.stage_params[:] = stage_params(cfg, compensation)
        self.params[:] = self.kind.params(cfg.controller.section, cfg)
        self.log_columns = LOG_COLUMNS + tuple(self.kind.log_columns)
        self._tick, self._log_row = self.kernels.servo_tick, self.kernels.log_row  # until warm_up
        self.log_units = {**LOG_UNITS, **self.kind.log_units}

    def __repr__(self) -> str:
        comp = "on" if self.stage_params["comp_on"][0] else "off"
        dt = float(self.stage_params["dt"][0])
        return f"<Controller {self.kind.name} at {1 / dt / 1e3:g} kHz, compensator {comp}, u_max {float(self.stage_params['u_max'][0]):g} A>"

    def records(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(stage_state, stage_params, state, params)``: views of the four records."""
        return self.stage_state, self.stage_params, self.state, self.params

    def warm_up(self) -> None:
        """Call the kernels once on scratch copies, so that the first tick of a run pays
        no first-call cost (the first dispatch on these record types takes ~0.2 ms).
        Once per process and kind: the entry points checked then serve every later
        controller of the kind (its ``buf`` has the kind's dtype, whatever the config)."""
        entries = _WARM.get(self.kernels.servo_tick)
        if entries is None:
            scratch = self.buf.copy()
            self.kernels.servo_start(scratch, 0.0, 0.0, 0.0)
            # the tick and the log row without per-call dispatch, checked on the scratch copy
            entries = _WARM[self.kernels.servo_tick] = (
                entry_point(self.kernels.servo_tick, scratch, 0.0, 0.0, 0.0, 0.0),
                entry_point(self.kernels.log_row, np.empty(len(self.log_columns)), 0, 1.0, 0.0, 0.0, scratch))  # fmt: skip
        self._tick, self._log_row = entries

    def start(self, x: float, v: float, u_now: float) -> None:
        """Take over bumplessly at position ``x`` (m), velocity ``v`` (m/s, NaN if not
        measured) with ``u_now`` (A) applied."""
        self.kernels.servo_start(self.buf, x, v, u_now)

    def tick(self, x: float, v: float, r: float, u_exc: float) -> float:
        """One sample at measured ``x`` (m), ``v`` (m/s, NaN if not measured), reference
        ``r`` (m, from the holding position), excitation ``u_exc`` (A); returns the
        current command (A)."""
        return self._tick(self.buf, x, v, r, u_exc)

    def log_row(self, row: np.ndarray, k: int, dt: float, x: float, u_exc: float) -> None:
        """Fill ``row`` (length ``len(log_columns)``) for tick ``k``."""
        self.kernels.log_row(row, k, dt, x, u_exc, self.buf)

    def unchecked_log_row(self, row: np.ndarray, k: int, dt: float, x: float, u_exc: float) -> None:
        """:meth:`log_row` through the kernel's entry point, without Numba's argument
        checks: only for rows the runtime itself owns (a 1-D contiguous float64 row of
        ``len(log_columns)`` of a run log), after :meth:`warm_up`."""
        self._log_row(row, k, dt, x, u_exc, self.buf)

    @property
    def e(self) -> float:
        """The latest position error (m)."""
        return float(self.stage_state[0]["e"])

"""The simulated drive's arrays: plant parameters, initial state, exact mode matrices.

:func:`build_plant` turns a :class:`~servo.config.DriveConfig` into the record arrays that
:func:`kernels.plant.plant_step` and :func:`kernels.plant.plant_measure` work on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from kernels.plant import PLANT_PARAMS, PLANT_STATE
from servo import physics
from servo.config import DriveConfig
from servo.errors import ConfigError
from servo.physics.time_delay import split_delay  # noqa: F401  (importable from here, as before)


@dataclass
class SimPlant:
    """Everything the plant kernels touch, preallocated.

    ``params``/``state``: one-element :data:`~kernels.plant.PLANT_PARAMS` /
    :data:`~kernels.plant.PLANT_STATE` records; ``q`` (n_modes, 2) modal position and
    velocity; ``mab`` (n_modes, 2, 6) exact discretisation of each mode over the two
    constant-input intervals of a sample; ``gain`` (n_modes,) modal gains; ``ubuf``
    (delay_whole + 2,) past commands of the input delay; ``u_hold`` the current (A) that
    holds the arm at rest at its initial position.
    """

    params: np.ndarray
    state: np.ndarray
    q: np.ndarray
    mab: np.ndarray
    gain: np.ndarray
    ubuf: np.ndarray
    u_hold: float


_BLAS: list = []


def _one_blas_thread():
    """BLAS limited to one thread for the block: a 3x3 matrix exponential gains nothing
    from OpenBLAS's threads, and waking them cost 13-30 ms per call with the cores busy
    (0.03 ms on one thread; the same bits).  The controller is made once per process."""
    if not _BLAS:
        from threadpoolctl import ThreadpoolController

        _BLAS.append(ThreadpoolController())
    return _BLAS[0].limit(limits=1, user_api="blas")


def mode_matrices(hz, zeta, J: float, h1: float, h2: float) -> np.ndarray:
    """Exact zero-order-hold discretisation of ``q'' + 2*zeta*w*q' + w^2*q = u/J`` over
    intervals of ``h1`` and ``h2`` seconds.  Returns (n, 2, 6): ``a11 a12 a21 a22 b1 b2``."""
    out = np.zeros((len(hz), 2, 6))
    with _one_blas_thread():
        _fill_modes(out, hz, zeta, J, h1, h2)
    return out


def _fill_modes(out: np.ndarray, hz, zeta, J: float, h1: float, h2: float) -> None:
    for i, (f, z) in enumerate(zip(hz, zeta)):
        w = 2.0 * math.pi * f
        m = np.zeros((3, 3))
        m[0, 1] = 1.0
        m[1, 0] = -w * w
        m[1, 1] = -2.0 * z * w
        m[1, 2] = 1.0 / J
        for j, h in enumerate((h1, h2)):
            e = expm(m * h)
            out[i, j] = (e[0, 0], e[0, 1], e[1, 0], e[1, 1], e[0, 2], e[1, 2])


def plant_params(d: DriveConfig, dt: float) -> np.ndarray:
    """The :data:`~kernels.plant.PLANT_PARAMS` record of a drive config at period ``dt``:
    each physical effect's fields (:func:`servo.physics.plant_values`), the sample period
    and the integration's sub-steps."""
    p = np.zeros(1, PLANT_PARAMS)
    physics.fill(p, {**physics.plant_values(d, dt), "dt": dt, "n_sub": d.substeps})
    return p


def holding_current(d: DriveConfig, x: float) -> float:
    """Current (A) that balances the forces at rest at ``x`` (each effect's
    :attr:`~servo.physics.base.Effect.rest_force`, the pivot's Dahl element relaxed,
    ``H = 0``) through the force constant there (:func:`servo.physics.force_gain`): what
    reaches the arm (:func:`holding_command` the command that gives it)."""
    return physics.rest_force(d, x) / physics.force_gain(d, x)


def holding_command(d: DriveConfig, u: float) -> float:
    """The command (A) whose current through the drive's input elements (each effect's
    :attr:`~servo.physics.base.Effect.command_for`) is ``u`` (A)."""
    return physics.command_for(d, u)


def build_plant(d: DriveConfig, dt: float) -> SimPlant:
    """Fresh plant arrays for drive ``d`` sampled every ``dt`` s: the arm at rest at
    ``d.initial_position``, held there by :func:`holding_current` (``u_hold`` the command
    that gives it through the input elements), the flexible modes at their static deflection
    under that current."""
    whole, frac = split_delay(d.input_delay_s, dt)
    u_arm = holding_current(d, d.initial_position)
    u_hold = holding_command(d, u_arm)
    if abs(u_hold) > d.current_limit:
        raise ConfigError(
            f"config: drive.initial_position needs {u_hold:.3g} A to hold, beyond drive.current_limit"
        )
    state = np.zeros(1, PLANT_STATE)
    state["x"] = d.initial_position
    with np.errstate(all="ignore"):  # an overflow shows as a non-finite array, checked below
        q = np.zeros((len(d.mode_hz), 2))
        q[:, 0] = u_arm / (d.J * (2.0 * np.pi * np.asarray(d.mode_hz)) ** 2)  # static deflection
        plant = SimPlant(
            params=plant_params(d, dt),
            state=state,
            q=q,
            mab=mode_matrices(d.mode_hz, d.mode_zeta, d.J, frac, dt - frac),
            gain=np.asarray(d.mode_gain, dtype=float),
            ubuf=np.full(whole + 2, u_hold),
            u_hold=u_hold,
        )
        # the measured-side positions (the sensor low-pass's output, the load behind a
        # backlash: PLANT_STATE's ``y_*``) start settled on the measured position at rest
        for name in (n for n in PLANT_STATE.names if n.startswith("y_")):
            state[name] = d.initial_position + float(np.dot(plant.gain, q[:, 0]))
    bad = [name for name, a in (("parameters", plant.params.view(np.float64)), ("modes", plant.mab), ("state", q))
           if not np.all(np.isfinite(a))]  # fmt: skip
    if bad or not np.isfinite(u_hold):
        raise ConfigError(f"config: the drive's model is not finite with these values ({', '.join(bad) or 'holding current'} "
                          f"overflow at J = {d.J:g}, sample period {dt:g} s): check the [drive] section")  # fmt: skip
    return plant

"""Simulated output: a model's position predicted a short horizon ahead from measured
states, under the recorded input, and its error.

The plant integrates: a force error becomes a position error that grows without bound,
so a model is judged on many short simulations rather than one long one.  From every
start ``k`` (one every ``horizon`` samples) the model's drive is set to the state
estimated at ``k`` and stepped ``horizon`` samples under the recorded input:

* rigid position and velocity: the filtered ``xf[k]``, ``vf[k]`` less the modes' part;
* the Dahl force (a hidden state): the model's Dahl estimator run along the recorded
  path up to ``k`` (the same column the force fit uses);
* the modes (hidden too): driven by the recorded input from the start of the recording.

The model's drive is the simulated drive's own kernel (:func:`kernels.plant.plant_step`)
with the fitted parameters: every vocabulary term maps onto a field of the drive
(:meth:`~servo.physics.base.DriveMap.to_drive`; the input terms are applied to the
input beforehand: clipped, then delayed).  The error is
normalised by what the force model has to explain, the motion that is not coasting::

    NRMSE = ||x_meas[k+i] - x_pred[k+i]|| / ||x_meas[k+i] - xf[k] - vf[k]*i*dt||

over all starts and steps ``i = 1..horizon``: 0 is a perfect prediction, 1 is no better
than coasting at the initial velocity.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kernels.plant import PLANT_STATE
from kernels.predict import mode_trace, multistep
from servo.diagnose.fit import Fit
from servo.diagnose.model import Design
from servo import physics
from servo.config import DriveConfig
from servo.physics import EFFECTS
from servo.physics.base import Simulation
from servo.runtime.simplant import mode_matrices, plant_params

#: default horizon, in row spacings (decimation factor samples each)
HORIZON_ROWS = 10
TINY = 1e-300


@dataclass
class Prediction:
    """``starts`` (S,) start samples; ``pred``/``meas``/``coast`` (S, H) predicted and
    measured positions and the coasting reference at samples ``starts + 1..H``."""

    starts: np.ndarray
    pred: np.ndarray
    meas: np.ndarray
    coast: np.ndarray

    def sse(self) -> tuple[np.ndarray, np.ndarray]:
        """Per start: squared prediction error and squared non-coasting motion (S,)."""
        e = np.sum((self.meas - self.pred) ** 2, axis=1)
        d = np.sum((self.meas - self.coast) ** 2, axis=1)
        return e, d

    def nrmse(self, mask: np.ndarray | None = None) -> float:
        e, d = self.sse()
        m = np.ones(e.size, bool) if mask is None else mask
        return float(np.sqrt(e[m].sum() / max(d[m].sum(), TINY)))


class Unsimulable(Exception):
    """The model cannot be simulated (no positive inertia)."""


def drive_params(fit: Fit, design: Design) -> tuple[np.ndarray, dict]:
    """The :data:`~kernels.plant.PLANT_PARAMS` record of a fitted model and its modes
    (``{"hz", "zeta", "gain"}``): the model's ``[drive]`` fields (:meth:`Fit.drive`, each
    term's own) on the plant, with no stops, no limit, no delay (the input terms are
    applied beforehand), no noise.  Raises :class:`Unsimulable` without a positive ``J``."""
    d = fit.drive()
    sig = design.sig
    if not fit.mass() > 0:
        raise Unsimulable("the model has no positive inertia J: its output cannot be simulated")
    stroke = 10.0 * float(np.max(np.abs(sig.x))) + 1.0  # stops the motion never reaches
    sim = Simulation(fit.combined(), stroke, max(float(np.max(np.abs(sig.u))), TINY))
    drive = DriveConfig(**physics.simulated_drive(d, sim), substeps=2)
    rec = plant_params(drive, sig.dt)  # the runtime's one mapping of a drive onto the plant's record
    return rec, {"hz": d["mode_hz"], "zeta": d["mode_zeta"], "gain": d["mode_gain"]}


def starts_in(design: Design, rows: np.ndarray, horizon: int) -> np.ndarray:
    """Start samples, one every ``horizon``, spanning the full-rate samples of ``rows``."""
    idx = np.flatnonzero(rows)
    if idx.size == 0:
        return np.zeros(0, np.int64)
    keep = design.sig.keep
    lo, hi = keep[idx[0]], min(keep[idx[-1]], design.sig.n - horizon - 2)
    return np.arange(lo, hi, horizon, dtype=np.int64)


def predict(design: Design, fit: Fit, starts: np.ndarray, horizon: int) -> Prediction:
    """Short-horizon predictions of ``fit`` from ``starts`` (see module doc)."""
    sig = design.sig
    pp, modes = drive_params(fit, design)
    u = np.ascontiguousarray(design.u_eff(fit.model), dtype=float)
    J = float(pp["J"][0])
    nm = len(modes["hz"])
    mab = mode_matrices(modes["hz"], modes["zeta"], J, 0.0, sig.dt)
    gain = np.asarray(modes["gain"], dtype=float)
    qtr = np.zeros((sig.n, nm, 2))
    if nm:
        q = np.zeros((nm, 2))
        q[:, 0] = u[0] / (J * (2 * np.pi * np.asarray(modes["hz"])) ** 2)
        mode_trace(mab, u, q, qtr)
    q0 = np.ascontiguousarray(qtr[starts])
    x0 = sig.xf[starts] - (q0[:, :, 0] @ gain if nm else 0.0)
    v0 = sig.vf[starts] - (q0[:, :, 1] @ gain if nm else 0.0)
    H0 = np.zeros(starts.size)
    P = fit.combined()
    for t in fit.model.terms:  # a term that holds a hidden state of the plant (a Dahl element's force)
        h = EFFECTS[t.physics].drive_map.state(design, t.params, P, u, pp)
        if h is not None:
            H0 = h[starts]
            break
    out = np.zeros((starts.size, horizon))
    ps = np.zeros(1, PLANT_STATE)
    multistep(ps, pp, np.zeros((nm, 2)), mab, gain, np.zeros(2), u, np.ascontiguousarray(x0, dtype=float),
              np.ascontiguousarray(v0, dtype=float), np.ascontiguousarray(H0, dtype=float), q0, starts, horizon, out)  # fmt: skip
    i = np.arange(1, horizon + 1)
    idx = starts[:, None] + i[None, :]
    meas = sig.x[idx]
    coast = sig.xf[starts][:, None] + sig.vf[starts][:, None] * i[None, :] * sig.dt
    return Prediction(starts, out, meas, coast)


def horizon_samples(design: Design, horizon_s: float | None = None) -> int:
    """Horizon in samples: ``horizon_s`` or :data:`HORIZON_ROWS` row spacings."""
    if horizon_s is None:
        return HORIZON_ROWS * design.sig.settings.decimate
    return max(1, int(round(horizon_s / design.sig.dt)))


__all__ = ["HORIZON_ROWS", "Prediction", "Unsimulable", "drive_params", "horizon_samples", "predict",
           "starts_in"]  # fmt: skip

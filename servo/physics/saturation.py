"""The amplifier's current limit: the input clipped at ``+-level``.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import numpy as np

from servo.fields import MAGNITUDE_MAX
from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, SignalPath, Term


class Clipping(SignalPath):
    """The saturation on the input's path: the amplifier clips first, then the delay."""

    def transform(self, u, theta, dt):
        return np.clip(u, -theta["level"], theta["level"])

    def idle(self, params, u):
        return params["level"] >= (float(np.max(np.abs(u))) if u.size else 0.0)  # clips nothing


class Saturation(Term):
    name, thetas, units = "input_saturation", ("level",), {"level": "F"}
    doc = "the input is clipped at +-level before it reaches the arm (amplifier current limit)"
    QUANTILES = (0.9, 0.95, 0.97, 0.98, 0.99, 0.995, 0.998)
    MIN_CLIPPED = 10  # samples
    path = Clipping(kind="input", path_order=0)

    def _levels(self, d):
        au = np.abs(d.sig.u[d.train_samples])
        lv = np.unique(np.quantile(au, self.QUANTILES))
        return [float(L) for L in lv if np.count_nonzero(au > L) >= self.MIN_CLIPPED and L > 0]

    def grid(self, d, model):
        return [{"level": L} for L in self._levels(d)]

    def bounds(self, d, model):
        lv = self._levels(d)
        au = np.abs(d.sig.u[d.train_samples])
        return {"level": (lv[0] if lv else 0.0, float(np.quantile(au, 0.999)), False)}


class SaturationDrive(DriveMap):
    """The input_saturation term in the simulated drive's ``[drive]`` section."""

    name = "input_saturation"
    # without a saturation the model has no limit: the config's largest magnitude (its
    # default, 1 A, would clip a recording in N when the file is held against it)
    absent = {"current_limit": MAGNITUDE_MAX}

    def to_drive(self, P, fit):
        return {"current_limit": P[self.name]["level"]}

    def from_drive(self, d):
        return [({"level": d.current_limit}, ())]

    def in_drive(self, d):
        return False  # every drive has its amplifier's limit: a term only where a diagnosis finds one clipping


def _calibrate(log, size):
    """The limit that clips a fraction ``size`` of the samples of a first run's command."""
    return {"current_limit": float(np.quantile(np.abs(log["u"]), 1.0 - size))}


_STUDY = Concealment("input_saturation", "-", "fraction of the samples clipped", (0.002, 0.005, 0.01, 0.02, 0.05), 0.05,
                     calibrate=_calibrate)


EFFECT = Effect(
    "input_saturation", "the amplifier's current limit",
    drive=dict(current_limit=P(1.0, "A", "amplifier current limit", 0.0, None, lo_open=True)),
    plant=lambda d, dt: {"u_max": d.current_limit},
    term=Saturation(),
    not_cancellable="a saturation is a limit, not a force: set [controller] current_limit at or below it so "
                    "the loop knows the room it has",
    drive_map=SaturationDrive(),
    study=_STUDY,
    simulated=lambda d, sim: {"current_limit": 1e300},  # applied to the input beforehand
)  # fmt: skip

"""A first-order low-pass on the position sensor (its cutoff ``sensor_cutoff_hz``).

The effect's config field, plant mapping, drive map and concealment.  Its diagnosis
term builds on the diagnosis's signal path (it corrects the other terms' columns for the
lag), so it lives in :mod:`servo.diagnose.sensor_lag` and registers itself with
:func:`servo.physics.register_term`.
"""
from __future__ import annotations

import math

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect


class SensorLagDrive(DriveMap):
    """The sensor_lag term in the simulated drive's ``[drive]`` section."""

    name = "sensor_lag"
    absent = {"sensor_cutoff_hz": 0.0}

    def to_drive(self, P, fit):
        return {"sensor_cutoff_hz": P[self.name]["cutoff_hz"]}

    def from_drive(self, d):
        fc = d.sensor_cutoff_hz
        return [({"time_constant_s": 1.0 / (2 * math.pi * fc)}, ())] if fc > 0 else []


def _conceal(size):
    return {"sensor_cutoff_hz": 1.0 / (2 * math.pi * size)}


#: sizes: the time constant, from 1.2 samples at 50 kHz (the shortest lag tried at
#: decimation by 10, servo.diagnose.sensor_lag.SensorLag.DELAY_LIKE) to 4.8
_STUDY = Concealment("sensor_lag", "s", "sensor time constant (first-order low-pass, cutoff 1/(2*pi*tau))",
                     (24e-6, 32e-6, 48e-6, 64e-6, 96e-6), 64e-6, fields=_conceal)  # fmt: skip


def _plant(d, dt):
    if d.sensor_cutoff_hz > 0:
        return {"sensor_a": 1.0 - math.exp(-2.0 * math.pi * d.sensor_cutoff_hz * dt)}
    return {"sensor_a": 0.0}


EFFECT = Effect(
    "sensor_lag", "first-order low-pass on the measured position",
    drive=dict(sensor_cutoff_hz=P(0.0, "Hz", "first-order low-pass on the measured position, before noise (0: none)", 0.0)),
    plant=_plant,
    drive_map=SensorLagDrive(),
    study=_STUDY,
    not_cancellable="a low-pass on the position sensor is a lag in the loop, not a force: raise the sensor's "
                    "bandwidth (its filter's cutoff well above the crossover), or estimate the position ahead of the "
                    "filter with an observer that inverts it",
    simulated=lambda d, sim: {"sensor_cutoff_hz": 0.0},
)  # fmt: skip

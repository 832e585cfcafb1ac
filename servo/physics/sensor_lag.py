"""A first-order low-pass on the position sensor (its cutoff ``sensor_cutoff_hz``).

The effect's config field and plant mapping.  Its diagnosis term builds on the
diagnosis's signal path (it corrects the other terms' columns for the lag), so it lives
in :mod:`servo.diagnose.sensor_lag` and registers itself with
:func:`servo.physics.register_term`.
"""
from __future__ import annotations

import math

from servo.fields import P
from servo.physics.base import Effect


def _plant(d, dt):
    if d.sensor_cutoff_hz > 0:
        return {"sensor_a": 1.0 - math.exp(-2.0 * math.pi * d.sensor_cutoff_hz * dt)}
    return {"sensor_a": 0.0}


EFFECT = Effect(
    "sensor_lag", "first-order low-pass on the measured position",
    drive=dict(sensor_cutoff_hz=P(0.0, "Hz", "first-order low-pass on the measured position, before noise (0: none)", 0.0)),
    plant=_plant,
    not_cancellable="a low-pass on the position sensor is a lag in the loop, not a force: raise the sensor's "
                    "bandwidth (its filter's cutoff well above the crossover), or estimate the position ahead of the "
                    "filter with an observer that inverts it",
)  # fmt: skip

"""Sensor noise on the measured position and velocity, and whether the drive measures velocity.

The effect's config fields and plant mapping; the diagnosis estimates the noise (its
rows' weights) but does not name it as a term.
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import Effect

EFFECT = Effect(
    "sensor_noise", "sensor noise (position, velocity)",
    drive=dict(
        position_noise=P(1.0e-9, "m", "position sensor noise (std)", 0.0),
        velocity_noise=P(1.0e-6, "m/s", "velocity sensor noise (std)", 0.0),
        measures_velocity=P(True, "-", "the drive measures velocity (the paper's LDV)"),
    ),
    plant=lambda d, dt: {"noise_x": d.position_noise, "noise_v": d.velocity_noise,
                         "has_velocity": 1.0 if d.measures_velocity else 0.0},
    not_cancellable="noise is not a force: nothing to cancel (a quieter sensor, or a lower velocity cutoff)",
    simulated=lambda d, sim: {"position_noise": 0.0, "velocity_noise": 0.0, "measures_velocity": False},
)  # fmt: skip

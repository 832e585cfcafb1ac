"""Backlash between motor and load: the sensor reads a load that follows the motor
through a play of half-gap ``backlash_half_gap``.

The effect's config field, plant mapping and documentation entry
(:class:`~servo.physics.base.Effect`).

**The model.**  The voice coil drives the motor side (the arm of the force balance, its
position ``x``); the position sensor reads the load, which follows it through a play
(the load's inertia neglected, held by its own friction while the gap is open): the
load stands while the motor moves inside the gap and is pushed along at the gap's edge,
``y = play(x, b)``::

    y[k] = min(max(y[k-1], x[k] - b), x[k] + b)

(:mod:`kernels.plant`: on the motor's position with its modes, once per sample, before
the sensor's low-pass, noise and quantisation).
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import Effect

EFFECT = Effect(
    "backlash", "play between motor and load: the sensor reads a load that follows the motor through a gap",
    drive=dict(backlash_half_gap=P(0.0, "m", "half the play between the motor and the load the sensor reads (0: "
                                   "none)", 0.0)),
    plant=lambda d, dt: {"backlash": d.backlash_half_gap},
    not_cancellable="a play between the motor and the measured load is not a force on the motor: a force "
                    "cannot move the load across the gap faster than the motor crosses it, and the loop sees "
                    "the load stand at every reversal; measure the motor's position too (close the loop on it, "
                    "or use a dual-loop with the load's sensor outside), or preload the joint",
)  # fmt: skip

"""The vocabulary of physics a diagnosis can name: the terms of :mod:`servo.physics`.

Each physical effect's diagnosis term lives in its module, ``servo/physics/<effect>.py``
(:class:`servo.physics.base.Term`: its columns, parameters and grid); the registry
:mod:`servo.physics` gathers them into :data:`VOCABULARY`.  This module keeps the
names the diagnosis has always imported from here.
"""
from __future__ import annotations

from servo.physics import BASELINE_TERMS, NAMES, VOCABULARY, register_term
from servo.physics.asymmetric import Asymmetric
from servo.physics.base import Concealment, Term
from servo.physics.cogging import Cogging
from servo.physics.coulomb import Coulomb
from servo.physics.hysteresis import Hysteresis
from servo.physics.inertia import Inertia
from servo.physics.offset import Offset
from servo.physics.position_gain import PositionGain
from servo.physics.quantization import Quantization
from servo.physics.resonance import Resonance
from servo.physics.saturation import Saturation
from servo.physics.stiffness import Stiffness
from servo.physics.stribeck import Stribeck
from servo.physics.time_delay import TimeDelay
from servo.physics.viscous import Viscous

#: the names the diagnosis used before the terms moved to servo.physics
Physics, Effect, register = Term, Concealment, register_term

__all__ = ["BASELINE_TERMS", "NAMES", "VOCABULARY", "Asymmetric", "Cogging", "Coulomb", "Effect", "Hysteresis",
           "Inertia", "Offset", "Physics", "PositionGain", "Quantization", "Resonance", "Saturation", "Stiffness",
           "Stribeck", "TimeDelay", "Viscous", "register"]  # fmt: skip

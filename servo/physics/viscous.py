"""Viscous friction ``B*x'``.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import (EQ9, VISCOUS, Concealment, Effect, Judging, OneField,
                                 OneFieldDrive, field_at, number, one_field, zero)


class Viscous(OneField):
    name, coefs, units = "viscous_friction", ("B",), {"B": "F*s/m"}
    doc = "viscous friction B*x'"
    judging = Judging(positive={"B": "the force grows against the motion: negative damping, not friction"})

    def full(self, d, theta, u_eff):
        return d.sig.vf


_STUDY = Concealment("viscous_friction", "A*s/m", "B", (1e-5, 2e-5, 5e-5, 1e-4, 2e-4), 5e-3, baseline="J,Fc,K,h0",
                     fixed={"B": 0.0}, fields=field_at("B"))  # fmt: skip


EFFECT = Effect(
    "viscous_friction", "viscous friction B*x'",
    drive=dict(B=P(2.0e-3, "A*s/m", "viscous friction", 0.0)),
    compensator=dict(B=P(2.0e-3, "A*s/m", "viscous friction estimate", None, None)),
    plant=one_field("B"),
    stage=one_field("B"),
    term=Viscous(),
    drive_map=OneFieldDrive("viscous_friction", "B"),
    study=_STUDY,
    leave_out=zero("B"),
    cancel=lambda d, how: [(EQ9, {"B": number(d, "B")})],
    forces=lambda f, stroke, speed: {} if speed is None else {VISCOUS: abs(number(f, "B")) * speed},
    rates=lambda f, J: {"viscous pole |B|/J": abs(number(f, "B")) / J},
)  # fmt: skip

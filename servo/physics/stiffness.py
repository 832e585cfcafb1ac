"""Bias stiffness ``K*x`` (the flex cable, the pivot's average slope).

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import math

from servo.fields import P
from servo.physics.base import (BIAS, EQ9, Concealment, Effect, OneField,
                                 OneFieldDrive, field_at, number, one_field, zero)


class Stiffness(OneField):
    name, coefs, units = "stiffness", ("K",), {"K": "F/m"}
    doc = "stiffness K*x (flex-cable bias, pivot's average slope)"

    def full(self, d, theta, u_eff):
        return d.sig.xf


_STUDY = Concealment("stiffness", "A/m", "K", (2e-3, 5e-3, 1e-2, 2e-2, 5e-2), 0.2, baseline="J,B,Fc,h0", fixed={"K": 0.0},
                     fields=field_at("K"))


EFFECT = Effect(
    "stiffness", "stiffness K*x (flex-cable bias)",
    drive=dict(K=P(0.1, "A/m", "flex-cable bias stiffness", None, None)),
    compensator=dict(K=P(0.1, "A/m", "bias stiffness estimate (eq. 2)", None, None)),
    plant=one_field("K"),
    stage=one_field("K"),
    term=Stiffness(),
    drive_map=OneFieldDrive("stiffness", "K"),
    study=_STUDY,
    leave_out=zero("K"),
    cancel=lambda d, how: [(EQ9, {"K": number(d, "K")})],
    rest_force=lambda d, x: d.K * x,
    forces=lambda f, stroke, speed: {BIAS: abs(number(f, "K")) * stroke},
    rates=lambda f, J: {"natural frequency sqrt(|K|/J)": math.sqrt(abs(number(f, "K")) / J)},
)  # fmt: skip

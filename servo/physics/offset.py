"""A constant force ``h0`` (the flex cable's bias offset).

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import numpy as np

from servo.fields import P
from servo.physics.base import (BIAS, EQ9, Concealment, Effect, OneField,
                                 OneFieldDrive, field_at, number, one_field, zero)


class Offset(OneField):
    name, coefs, units = "offset", ("h0",), {"h0": "F"}
    doc = "constant force h0"

    def full(self, d, theta, u_eff):
        return np.ones(d.sig.n)  # through the rows' filter too: its DC gain is 0.989, not 1


_STUDY = Concealment("offset", "A", "h0", (5e-6, 1e-5, 2e-5, 5e-5, 1e-4), 3e-4, baseline="J,B,Fc,K", fixed={"h0": 0.0},
                     fields=field_at("h0"))


EFFECT = Effect(
    "offset", "constant force h0 (flex-cable bias offset)",
    drive=dict(h0=P(2.0e-3, "A", "flex-cable bias offset", None, None)),
    compensator=dict(h0=P(2.0e-3, "A", "bias offset estimate (eq. 2)", None, None)),
    plant=one_field("h0"),
    stage=one_field("h0"),
    term=Offset(),
    drive_map=OneFieldDrive("offset", "h0"),
    study=_STUDY,
    leave_out=zero("h0"),
    cancel=lambda d, how: [(EQ9, {"h0": number(d, "h0")})],
    rest_force=lambda d, x: d.h0,
    forces=lambda f, stroke, speed: {BIAS: abs(number(f, "h0"))},
)  # fmt: skip

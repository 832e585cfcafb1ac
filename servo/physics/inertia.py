"""Inertia: the arm's equivalent mass, ``J*x''``.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import Effect, OneField, OneFieldDrive, Search, one_field


class Inertia(OneField):
    name, coefs, units = "inertia", ("J",), {"J": "F*s^2/m"}
    doc = "inertia J*x''"
    search = Search(gated=False)  # a mass does not appear half-way

    def full(self, d, theta, u_eff):
        return d.sig.af


EFFECT = Effect(
    "inertia", "inertia J*x'' (the arm's equivalent mass)",
    drive=dict(J=P(1.0e-3, "A*s^2/m", "normalised inertia (equivalent mass)", 1e-9, 1e3)),
    plant=one_field("J"),
    term=Inertia(),
    not_cancellable="the inertia is the plant the controller is designed for (eq. 10: J*x'' = u_n): it is "
                    "controlled, not cancelled",
    drive_map=OneFieldDrive("inertia", "J"),
)  # fmt: skip

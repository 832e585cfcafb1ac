"""Direction-dependent friction: ``B(+-) = B*(1 +- a)``, ``Fc(+-) = Fc*(1 +- a)``.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import numpy as np

from servo.fields import P
from servo.physics import coulomb
from servo.physics.base import SLIDING, VISCOUS, Concealment, DriveMap, Effect, Search, Term, number


class Asymmetric(Term):
    name, coefs, units = "asymmetric_friction", ("dB",), {"dB": "F*s/m", "b_asymmetry": "-"}
    doc = ("direction-dependent friction: B(+-) = B +- dB.  A direction-dependent Coulomb level "
           "Fc(+-) = Fc +- dFc adds dFc to every sliding row: it is an offset while the arm slides "
           "and is reported in the offset")  # fmt: skip
    search = Search(requires=("viscous_friction", "coulomb_friction", "offset"))

    def full(self, d, theta, u_eff):
        return np.abs(d.sig.vf)


class AsymmetricDrive(DriveMap):
    """The asymmetric_friction term in the simulated drive's ``[drive]`` section."""

    name = "asymmetric_friction"

    def to_drive(self, P, fit):
        B = P.get("viscous_friction", {}).get("B", 0.0)
        return {"b_asymmetry": P[self.name]["dB"] / B} if B else {}

    def from_drive(self, d):
        return [({}, (d.B * d.b_asymmetry,))] if d.b_asymmetry else []


def _conceal(size):
    return {"b_asymmetry": size, "fc_asymmetry": size}


def _leave_out(d):
    d["b_asymmetry"] = 0.0


_STUDY = Concealment("asymmetric_friction", "-", "fc_asymmetry = b_asymmetry", (0.01, 0.02, 0.05, 0.1, 0.2), 0.5,
                     fields=_conceal)


def _forces(f, stroke, speed):
    """What the asymmetry adds to the Coulomb element's largest level and (at ``speed``)
    to the viscous force, in the fields ``f`` of either section."""
    a = max(abs(number(f, "fc_asymmetry")), abs(number(f, "coulomb_asymmetry")))
    out = {SLIDING: a * coulomb.peak(f)}
    if speed is not None:
        out[VISCOUS] = abs(number(f, "b_asymmetry")) * abs(number(f, "B")) * speed
    return out


EFFECT = Effect(
    "asymmetric_friction", "direction-dependent viscous and Coulomb friction",
    drive=dict(
        fc_asymmetry=P(0.0, "-", "Coulomb asymmetry: Fc(+) = Fc*(1+a), Fc(-) = Fc*(1-a)", -1.0, 1.0),
        b_asymmetry=P(0.0, "-", "viscous asymmetry: B(+) = B*(1+a), B(-) = B*(1-a)", -1.0, 1.0),
    ),
    compensator=dict(
        b_asymmetry=P(0.0, "-", "viscous asymmetry: B(+) = B*(1+a), B(-) = B*(1-a) (cancels drive.b_asymmetry)", -1.0, 1.0),
        coulomb_asymmetry=P(0.0, "-", "its asymmetry: F(+) = F*(1+a), F(-) = F*(1-a)", -1.0, 1.0),
    ),
    plant=lambda d, dt: {"b_asym": d.b_asymmetry, "fc_asym": d.fc_asymmetry},
    stage=lambda c: {"b_asym": c.b_asymmetry, "coul_asym": c.coulomb_asymmetry},
    engaged=lambda c: bool(c.b_asymmetry),
    term=Asymmetric(),
    drive_map=AsymmetricDrive(),
    leave_out=_leave_out,
    study=_STUDY,
    simulated=lambda d, sim: {"fc_asymmetry": 0.0, "b_asymmetry": d.get("b_asymmetry", 0.0)},
    cancel=lambda d, how: [] if how.paper or not number(d, "b_asymmetry") else [
        ("asymmetric viscous friction", dict(b_asymmetry=number(d, "b_asymmetry")))],
    forces=_forces,
)  # fmt: skip

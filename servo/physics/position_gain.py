"""A force constant that varies over the stroke: ``kf(x) = 1 + kf_linear*x + kf_quadratic*x^2``.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import numpy as np

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, SignalPath, Term, number


class PositionGain(Term):
    name, coefs = "position_dependent_gain", ("kf_linear", "kf_quadratic")
    units = {"kf_linear": "1/m", "kf_quadratic": "1/m^2"}
    doc = "force constant varying over the stroke: the arm gets kf(x)*u, kf = 1 + kf_linear*x + kf_quadratic*x^2"
    path = SignalPath(uses_input=True)

    def full(self, d, theta, u_eff):
        ua = d.sig.force(u_eff)
        x = d.sig.xf
        return np.column_stack([-x * ua, -x * x * ua])


class PositionGainDrive(DriveMap):
    """The position_dependent_gain term in the simulated drive's ``[drive]`` section."""

    name = "position_dependent_gain"
    STROKE = 0.015  # m: the drive's kf fields are the changes at this stroke

    def to_drive(self, P, fit):
        g, s = P[self.name], self.STROKE
        return {"kf_linear": g["kf_linear"] * s, "kf_quadratic": g["kf_quadratic"] * s**2, "stroke": s}

    def from_drive(self, d):
        if d.kf_linear or d.kf_quadratic:
            return [({}, (d.kf_linear / d.stroke, d.kf_quadratic / d.stroke**2))]
        return []


def _simulated(d, sim):
    scale = sim.stroke / d.get("stroke", sim.stroke)  # the plant's kf fields are the changes at its stroke
    return {"kf_linear": d.get("kf_linear", 0.0) * scale, "kf_quadratic": d.get("kf_quadratic", 0.0) * scale**2}


def _conceal(size):
    return {"kf_linear": size}


def _leave_out(d):
    d.update(kf_linear=0.0, kf_quadratic=0.0)


_STUDY = Concealment("position_dependent_gain", "-", "kf_linear (force-constant change at +15 mm)",
                     (0.02, 0.05, 0.1, 0.2, 0.5), 0.5, fields=_conceal)  # fmt: skip


def _cancel(d, how):
    if how.paper or not (number(d, "kf_linear") or number(d, "kf_quadratic")):
        return []
    return [("position-dependent force constant", dict(kf_linear=number(d, "kf_linear"),
             kf_quadratic=number(d, "kf_quadratic"), kf_stroke=number(d, "stroke", 15e-3)))]


def _kf(d, x):
    """The force constant's factor ``kf(x)`` of the drive section ``d`` at ``x`` (m)."""
    r = x / d.stroke
    return 1.0 + d.kf_linear * r + d.kf_quadratic * r * r


EFFECT = Effect(
    "position_dependent_gain", "force constant varying over the stroke",
    drive=dict(
        kf_linear=P(0.0, "-", "force-constant change at +stroke, linear in x", -0.9, 0.9),
        kf_quadratic=P(0.0, "-", "force-constant change at +-stroke, quadratic in x", -0.9, 0.9),
    ),
    compensator=dict(
        kf_linear=P(0.0, "-", "force-constant change at +stroke, linear in x (the command is divided by kf(x))", -0.9, 0.9),
        kf_quadratic=P(0.0, "-", "force-constant change at +-stroke, quadratic in x", -0.9, 0.9),
        kf_stroke=P(15e-3, "m", "the stroke the force-constant terms refer to", 0.0, None, lo_open=True),
        kf_authority=P(0.5, "-", "the force-constant divisor kf(x) is held within 1 +- this", 0.0, 0.95, lo_open=True),
    ),
    plant=lambda d, dt: {"kf1": d.kf_linear, "kf2": d.kf_quadratic},
    stage=lambda c: {"kf1": c.kf_linear, "kf2": c.kf_quadratic, "kf_stroke": c.kf_stroke,
                     "kf_on": 1.0 if (c.kf_linear or c.kf_quadratic) else 0.0,
                     "kf_lo": 1.0 - c.kf_authority, "kf_hi": 1.0 + c.kf_authority},
    term=PositionGain(),
    drive_map=PositionGainDrive(),
    leave_out=_leave_out,
    study=_STUDY,
    simulated=_simulated,
    cancel=_cancel,
    force_gain=_kf,
)  # fmt: skip

"""A cubic spring ``k3*x^3`` beside the bias stiffness ``K*x``: hardening (``k3 > 0``) or
softening (``k3 < 0``).

A flex cable or a pivot whose stiffness grows (or falls) with the deflection: the
Duffing spring.  The diagnosis names it by one column, ``x^3`` of the measured motion
(odd and smooth, as the spring; ``x*|x|`` would be the quadratic law of another spring,
and ``x^3`` is the first term of any odd stiffness beyond ``K*x``), whose coefficient
``k3`` (F/m^3) takes either sign.  The compensator cancels it by the feed-forward
``k3*x^3`` of the measured position (``kernels/cancel.py``), within the authority.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import BIAS, Concealment, Effect, OneFieldDrive, Term, field_at, number, one_field, zero


class CubicSpring(Term):
    name, coefs, units = "cubic_spring", ("k3",), {"k3": "F/m^3"}
    doc = "a cubic spring k3*x^3 beside K*x (k3 > 0 hardening, k3 < 0 softening)"

    def full(self, d, theta, u_eff):
        x = d.sig.xf
        return x * x * x


class CubicSpringDrive(OneFieldDrive):
    """The cubic_spring term in the simulated drive's ``[drive]`` section (a drive with
    ``k3 = 0`` lacks it)."""

    def from_drive(self, d):
        return [({}, (d.k3,))] if d.k3 else []


def _cancel(d, how):
    if how.paper or not number(d, "k3"):
        return []
    return [("cubic spring", {"k3": number(d, "k3")})]


_STUDY = Concealment("cubic_spring", "A/m^3", "k3 (hardening; the arm moves within +-2 mm: k3 = 5e4 is 0.4 mA there, twice K*x)",
                     (2e3, 5e3, 1e4, 2e4, 5e4), 5e4, fields=field_at("k3"))


EFFECT = Effect(
    "cubic_spring", "a cubic spring k3*x^3 (hardening or softening)",
    drive=dict(k3=P(0.0, "A/m^3", "cubic spring k3*x^3 beside K*x (> 0 hardening, < 0 softening)", None, None)),
    compensator=dict(k3=P(0.0, "A/m^3", "cubic spring estimate: k3*x^3 fed forward (cancels drive.k3)", None, None)),
    plant=one_field("k3"),
    stage=one_field("k3"),
    engaged=lambda c: c.k3 != 0.0,
    term=CubicSpring(),
    drive_map=CubicSpringDrive("cubic_spring", "k3"),
    leave_out=zero("k3"),
    study=_STUDY,
    cancel=_cancel,
    rest_force=lambda d, x: d.k3 * x * x * x,
    forces=lambda f, stroke, speed: {BIAS: abs(number(f, "k3")) * stroke**3},
)  # fmt: skip

"""Coulomb friction beyond the Dahl element: ``Fc*sgn(x')``, a sliding level.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import SLIDING, Concealment, DriveMap, Effect, Judging, SignalPath, Term, number, one_field
from servo.physics.stribeck import bristles


class Coulomb(Term):
    name, coefs, units = "coulomb_friction", ("Fc",), {"Fc": "F"}

    doc = "Coulomb friction Fc*sgn(x')"
    judging = Judging(positive={"Fc": "a force pushing along the motion: not friction"})
    path = SignalPath(signs_by_input=True)

    def full(self, d, theta, u_eff):
        return d.sig.sign_for(u_eff)  # the sign the rows see: its switch placed between samples


class CoulombDrive(DriveMap):
    """The coulomb_friction term in the simulated drive's ``[drive]`` section."""

    name = "coulomb_friction"
    absent = {"Fc": 0.0, "Fs": 0.0}

    def to_drive(self, P, fit):
        Fc = P[self.name]["Fc"]
        return {"Fc": Fc, "Fs": Fc}  # exact sticking; a Stribeck term raises Fs

    def from_drive(self, d):
        return [({}, (d.Fc if d.Fs > 0 else 0.0,))]

    def in_drive(self, d):
        return d.Fc > 0  # a breakaway alone is the Stribeck term's


def _conceal(size):
    return {"Fc": size, "Fs": size}


def _simulated(d, sim):
    held = bristles(sim.P)  # a Stribeck rise held by bristles: the level beneath it (stribeck.bristles)
    return {"Fc": max(d["Fc"] - held[0], 0.0) if held is not None else d["Fc"]}


def _leave_out(d):
    d["Fs"] = max(d.get("Fs", 0.0) - d.get("Fc", 0.0), 0.0)  # a Stribeck rise found on its own stays
    d["Fc"] = 0.0


_STUDY = Concealment("coulomb_friction", "A", "Fc = Fs (Coulomb level)", (1e-6, 2e-6, 5e-6, 1e-5, 2e-5), 2e-4,
                     baseline="J,B,K,h0", fixed={"Fc": 0.0, "Fs": 0.0}, fields=_conceal)  # fmt: skip


def peak(f: dict) -> float:
    """The Coulomb element's largest level in the fields ``f`` (either section's, a dict):
    its sliding level ``|Fc|`` (``|coulomb_extra|``) or the Stribeck breakaway of the
    stribeck_friction effect, ``|Fs|`` (``|coulomb_static|``), whichever is larger."""
    return max(abs(number(f, "Fc")), abs(number(f, "coulomb_extra")), abs(number(f, "Fs")),
               abs(number(f, "coulomb_static")))  # fmt: skip


def _cancel(d, how):
    """The Coulomb element beyond the Dahl one (``kernels.cancel.coulomb_stribeck``): its
    sliding level, the Stribeck rise to a breakaway (the stribeck_friction effect's
    ``Fs``, ``stribeck_velocity``) and its asymmetry (asymmetric_friction's
    ``fc_asymmetry``), one term of the stage."""
    Fc, Fs = number(d, "Fc"), number(d, "Fs")
    if how.paper or not (Fc > 0 or Fs > 0):
        return []
    keys = dict(coulomb_extra=Fc, coulomb_static=Fs if Fs > Fc else 0.0, coulomb_asymmetry=number(d, "fc_asymmetry"))
    if Fs > Fc:
        keys["stribeck_velocity"] = number(d, "stribeck_velocity", 1e-3)
    return [("Coulomb friction beyond the Dahl element" + (" with its Stribeck rise" if Fs > Fc else ""), keys)]


EFFECT = Effect(
    "coulomb_friction", "Coulomb friction Fc*sgn(x') beyond the Dahl element",
    drive=dict(Fc=P(0.0, "A", "extra Coulomb (sliding) friction beyond the Dahl element", 0.0)),
    compensator=dict(coulomb_extra=P(0.0, "A", "Coulomb friction beyond the Dahl element, large motion (cancels drive.Fc)",
                                     0.0)),
    plant=one_field("Fc"),
    stage=lambda c: {"coul_c": c.coulomb_extra},
    engaged=lambda c: bool(c.coulomb_extra),
    term=Coulomb(),
    renamed={"compensator.coulomb": "coulomb_extra"},
    drive_map=CoulombDrive(),
    leave_out=_leave_out,
    study=_STUDY,
    simulated=_simulated,
    cancel=_cancel,
    forces=lambda f, stroke, speed: {SLIDING: peak(f)},
)  # fmt: skip

"""Stribeck friction: a breakaway level ``Fs`` above the sliding ``Fc`` at low speed.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import numpy as np

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, Term, geom, valid_speed


class Stribeck(Term):
    name, coefs, thetas = "stribeck_friction", ("dFs",), ("stribeck_velocity",)
    units = {"dFs": "F", "stribeck_velocity": "m/s", "Fs": "F"}  # Fs: a breakaway found at rest (breakaway.py)
    doc = "Stribeck friction (Fs - Fc)*exp(-(x'/vs)^2)*sgn(x'): higher friction at low speed"
    requires = ("coulomb_friction",)

    def implausible(self, params: dict) -> str:
        if params["dFs"] < 0:
            return (f"the best fit has dFs = {params['dFs']:.3g} < 0: friction lower at low speed than sliding, a "
                    "smooth (pre-sliding-like) rise, the opposite of a Stribeck peak")  # fmt: skip
        return ""

    def full(self, d, theta, u_eff):
        v = d.sig.vf
        return d.sig.sign_v * np.exp(-((v / theta["stribeck_velocity"]) ** 2))

    def _range(self, d):
        v = valid_speed(d)
        return max(2.0 * d.sig.v_threshold, float(np.quantile(v, 0.02))), float(np.quantile(v, 0.75))

    def grid(self, d, model):
        return [{"stribeck_velocity": float(v)} for v in geom(*self._range(d), 5)]

    def bounds(self, d, model):
        return {"stribeck_velocity": (*self._range(d), True)}


class StribeckDrive(DriveMap):
    """The stribeck_friction term in the simulated drive's ``[drive]`` section."""

    name = "stribeck_friction"

    def to_drive(self, P, fit):
        p = P[self.name]
        return {"Fs": P.get("coulomb_friction", {}).get("Fc", 0.0) + p["dFs"], "stribeck_velocity": p["stribeck_velocity"]}

    def from_drive(self, d):
        if d.Fs > d.Fc and d.Fs > 0:
            return [({"stribeck_velocity": d.stribeck_velocity}, (d.Fs - d.Fc,))]
        return []


#: the study's Coulomb level under the Stribeck rise it conceals, A
_SLIDING = 1e-3


def _conceal(size):
    return {"Fs": _SLIDING + size}


def _leave_out(d):
    d["Fs"] = d.get("Fc", 0.0)  # exact sticking, as the drive holds without the term


_STUDY = Concealment("stribeck_friction", "A", "Fs - Fc (Stribeck velocity 2 mm/s)",
                     (2e-5, 5e-5, 1e-4, 2e-4, 5e-4), 5e-4, fixed={"Fc": _SLIDING, "stribeck_velocity": 2e-3},
                     fields=_conceal)  # fmt: skip


EFFECT = Effect(
    "stribeck_friction", "Stribeck friction: higher friction at low speed",
    drive=dict(
        Fs=P(0.0, "A", "static (breakaway) friction of the Coulomb term, >= Fc", 0.0),
        stribeck_velocity=P(1.0e-3, "m/s", "Stribeck velocity of the Coulomb term", 0.0, None, lo_open=True),
    ),
    compensator=dict(
        coulomb_static=P(0.0, "A", "its Stribeck peak at low speed (cancels drive.Fs; 0: no Stribeck rise)", 0.0),
        stribeck_velocity=P(1.0e-3, "m/s", "Stribeck velocity of that term", 0.0, None, lo_open=True),
    ),
    plant=lambda d, dt: {"Fs": d.Fs, "vs": d.stribeck_velocity},
    stage=lambda c: {"coul_s": c.coulomb_static or c.coulomb_extra, "coul_vs": c.stribeck_velocity},
    engaged=lambda c: bool(c.coulomb_static),
    term=Stribeck(),
    drive_map=StribeckDrive(),
    leave_out=_leave_out,
    study=_STUDY,
    simulated=lambda d, sim: {"Fs": max(d["Fs"], 0.0) if d["Fc"] > 0 else 0.0,
                              "stribeck_velocity": d.get("stribeck_velocity", 1.0)},
    diagnosed_by="breakaway",
)  # fmt: skip

"""Stribeck friction: a breakaway level ``Fs`` above the sliding ``Fc`` at low speed.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import numpy as np

import math

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, Term, geom, valid_speed

#: the Stribeck curve's shape exponent ``delta`` of ``exp(-|x'/vs|^delta)``: 2 the
#: paper's Gaussian curve, 1 the exponential one, below 1 a cusp at rest; the grid's
#: values and the refinement's bounds (a Lorentzian ``1/(1 + r^2)`` lies near 1.5)
SHAPES = (0.6, 1.0, 2.0)
SHAPE_BOUNDS = (0.4, 3.0)
#: the shape the drive kernel and the compensator hold (Gaussian), and a term's shape
#: when none is given (a breakaway found at rest, a drive's fields)
GAUSSIAN = 2.0


def curve(v: np.ndarray, vs: float, delta: float = GAUSSIAN) -> np.ndarray:
    """The Stribeck curve's fall with speed, ``exp(-|v/vs|^delta)`` (dimensionless, as ``v``)."""
    return np.exp(-(np.abs(v / vs) ** delta))


def gaussian_velocity(vs: float, delta: float) -> float:
    """The Stribeck velocity (m/s) of the Gaussian curve with the same area under it as
    ``exp(-|v/vs|^delta)`` (the same impulse over a sweep through the low speeds): what a
    drive or compensator that holds only the Gaussian shape takes for another shape."""
    return float(vs * math.gamma(1.0 + 1.0 / delta) / math.gamma(1.5))


class Stribeck(Term):
    name, coefs, thetas = "stribeck_friction", ("dFs",), ("stribeck_velocity", "stribeck_shape")
    units = {"dFs": "F", "stribeck_velocity": "m/s", "stribeck_shape": "-", "Fs": "F"}  # Fs: a breakaway at rest
    doc = ("Stribeck friction (Fs - Fc)*exp(-|x'/vs|^delta)*sgn(x'): higher friction at low speed; delta the "
           "curve's shape (2 the paper's Gaussian, 1 exponential)")  # fmt: skip
    requires = ("coulomb_friction",)

    def from_physical(self, p: dict) -> tuple[dict, tuple]:
        theta = {"stribeck_velocity": p["stribeck_velocity"], "stribeck_shape": p.get("stribeck_shape", GAUSSIAN)}
        return theta, (p["dFs"],)

    def implausible(self, params: dict) -> str:
        if params["dFs"] < 0:
            return (f"the best fit has dFs = {params['dFs']:.3g} < 0: friction lower at low speed than sliding, a "
                    "smooth (pre-sliding-like) rise, the opposite of a Stribeck peak")  # fmt: skip
        return ""

    def full(self, d, theta, u_eff):
        return d.sig.sign_v * curve(d.sig.vf, theta["stribeck_velocity"], theta.get("stribeck_shape", GAUSSIAN))

    def _range(self, d):
        v = valid_speed(d)
        return max(2.0 * d.sig.v_threshold, float(np.quantile(v, 0.02))), float(np.quantile(v, 0.75))

    def grid(self, d, model):
        return [{"stribeck_velocity": float(v), "stribeck_shape": s} for s in SHAPES for v in geom(*self._range(d), 5)]

    def bounds(self, d, model):
        return {"stribeck_velocity": (*self._range(d), True), "stribeck_shape": (*SHAPE_BOUNDS, True)}


class StribeckDrive(DriveMap):
    """The stribeck_friction term in the simulated drive's ``[drive]`` section."""

    name = "stribeck_friction"

    def to_drive(self, P, fit):
        p = P[self.name]  # the drive's curve is Gaussian: another shape as the Gaussian of its area
        vs = gaussian_velocity(p["stribeck_velocity"], p.get("stribeck_shape", GAUSSIAN))
        return {"Fs": P.get("coulomb_friction", {}).get("Fc", 0.0) + p["dFs"], "stribeck_velocity": vs}

    def from_drive(self, d):
        if d.Fs > d.Fc and d.Fs > 0:
            return [({"stribeck_velocity": d.stribeck_velocity, "stribeck_shape": GAUSSIAN}, (d.Fs - d.Fc,))]
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

"""An input dead zone: the arm gets ``sgn(u)*max(|u| - width, 0)`` of the command.

A driver stage that passes nothing below a threshold (a class-B output stage's
crossover, a PWM's minimum pulse) removes a band of half-width ``width`` (A) from the
clipped command before it reaches the arm.  The diagnosis names it as an input term
(like the current limit): the recorded input through the dead zone, with a half-width
grid from the recorded ``|u|``.  The compensator cancels it with the inverse dead zone
on the command, ``u + sgn(u)*dead_zone`` (``kernels/cancel.py``), which adds at most
the compensator's ``authority`` (so an over-estimated half-width is a bounded relay, not
an unbounded one).

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import math

import numpy as np

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, SignalPath, Term, field_at, number, zero


class Band(SignalPath):
    """The dead zone on the input's path: after the amplifier's clipping, before the delay
    (as in the drive)."""

    def transform(self, u, theta, dt):
        w = theta["width"]
        return u - np.clip(u, -w, w)

    def idle(self, params, u):
        return not params["width"] > 0.0


class DeadZone(Term):
    name, thetas, units = "dead_zone", ("width",), {"width": "F"}
    doc = "the input loses a band of half-width width: the arm gets sgn(u)*max(|u| - width, 0) (driver dead zone)"
    #: the half-widths tried: these quantiles of the recorded |u| (training samples)
    QUANTILES = (0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6)
    MIN_INSIDE = 10  # samples within the band
    #: a half-width must pass at least this share of the recorded mean ``|u|``: a band as
    #: wide as a binary input's level (a PRBS's ``|u|`` is one value) passes nothing, and
    #: the force balance of a zero input is met by all-zero coefficients (an open-loop PRBS
    #: lost its delay, lag and modes to a "dead zone" of its whole amplitude, J fitted 0)
    PASS_MIN = 0.1
    path = Band(kind="input", path_order=0.5)

    @classmethod
    def widest(cls, au: np.ndarray) -> float:
        """The largest half-width that passes :data:`PASS_MIN` of the mean of ``au``
        (``|u|``, (n,)): ``mean(max(au - w, 0))`` falls with ``w``; solved on the sorted
        values (0 for an input that is all zero)."""
        a = np.sort(np.asarray(au, dtype=float))[::-1]
        n = a.size
        if n == 0 or not a[0] > 0:
            return 0.0
        need = cls.PASS_MIN * a.sum()
        c = np.cumsum(a)
        above = c - np.arange(1, n + 1) * a  # the pass at w = a[i] (rising with i)
        i = max(int(np.searchsorted(above, need)), 1)  # w in [a[i], a[i-1]], i values beyond it
        return max(float((c[i - 1] - need) / i), 0.0)

    def _widths(self, d):
        au = np.abs(d.sig.u[d.train_samples])
        w = np.unique(np.quantile(au, self.QUANTILES))
        top = self.widest(au)
        return [float(v) for v in w if 0 < v <= top and np.count_nonzero(au < v) >= self.MIN_INSIDE]

    def grid(self, d, model):
        return [{"width": w} for w in self._widths(d)]

    def bounds(self, d, model):
        w = self._widths(d)
        au = np.abs(d.sig.u[d.train_samples])
        return {"width": (0.5 * w[0] if w else 0.0, min(float(np.quantile(au, 0.7)), self.widest(au)), False)}


class DeadZoneDrive(DriveMap):
    """The dead_zone term in the simulated drive's ``[drive]`` section."""

    name = "dead_zone"
    absent = {"dead_zone": 0.0}

    def to_drive(self, P, fit):
        return {"dead_zone": P[self.name]["width"]}

    def from_drive(self, d):
        return [({"width": d.dead_zone}, ())] if d.dead_zone > 0 else []


def _cancel(d, how):
    if how.paper or not number(d, "dead_zone") > 0:
        return []
    return [("input dead zone (its inverse on the command)", {"dead_zone": number(d, "dead_zone")})]


def _stage(c):
    """The inverse's half-width, at most the compensator's authority (when it has one)."""
    w = c.dead_zone
    return {"dz_w": min(w, c.authority) if c.authority > 0 else w}


#: the null drive's PI loop (a double integrator under a lead) is conditionally stable: a
#: half-width of 1 mA (a third of the median |u|) lowers its gain into a diverging limit cycle
_STUDY = Concealment("dead_zone", "A", "half-width of the input dead zone", (5e-5, 1e-4, 2e-4, 3e-4, 5e-4), 5e-4,
                     fields=field_at("dead_zone"))


EFFECT = Effect(
    "dead_zone", "an input dead zone (the driver passes nothing below a threshold)",
    drive=dict(dead_zone=P(0.0, "A", "input dead zone half-width: the arm gets sgn(u)*max(|u| - dead_zone, 0) of the "
                                     "clipped command", 0.0)),
    compensator=dict(dead_zone=P(0.0, "A", "inverse dead zone: sgn(u)*dead_zone added to the command (at most the "
                                          "authority; cancels drive.dead_zone)", 0.0)),
    plant=lambda d, dt: {"dz_width": d.dead_zone},
    stage=_stage,
    term=DeadZone(),
    drive_map=DeadZoneDrive(),
    leave_out=zero("dead_zone"),
    study=_STUDY,
    simulated=lambda d, sim: {"dead_zone": 0.0},  # applied to the input beforehand
    cancel=_cancel,
    command_for=lambda d, u: u + math.copysign(d.dead_zone, u) if d.dead_zone > 0.0 and u != 0.0 else u,
    forces=lambda f, stroke, speed: {"input dead zone's half-width": abs(number(f, "dead_zone"))},
)  # fmt: skip

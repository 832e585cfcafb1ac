"""Backlash between motor and load: the sensor reads a load that follows the motor
through a play of half-gap ``backlash_half_gap``.

The effect's config field, plant mapping, diagnosis term, drive map, concealment and
documentation entry (:class:`~servo.physics.base.Effect`).

**The model.**  The voice coil drives the motor side (the arm of the force balance, its
position ``x``); the position sensor reads the load, which follows it through a play
(the load's inertia neglected, held by its own friction while the gap is open): the
load stands while the motor moves inside the gap and is pushed along at the gap's edge,
``y = play(x, b)``::

    y[k] = min(max(y[k-1], x[k] - b), x[k] + b)

(:mod:`kernels.plant`: on the motor's position with its modes, once per sample, before
the sensor's low-pass, noise and quantisation).

**How it enters the force balance.**  The force balance holds for the motor,
``x = y + e`` with ``e`` the motor's place in the gap: ``e = s*b`` while the load moves
in direction ``s`` (pushed at the gap's edge), and across a *dwell* (the load standing
while the motor crosses the gap, from its reversal at ``t1`` with ``e' = 0`` to the
load's restart at ``t2``) a path from ``s_before*b`` to ``s_after*b``.  At ``t2`` the
massless load takes the motor's velocity ``v2`` at once: the measured position has a
kink, its acceleration an impulse ``v2*delta(t - t2)`` that no force explains (the
force balance of the measured motion misses ``J*e''``).  The rows near a dwell are
kept out of every fit (the direction is uncertain there, ``servo.diagnose.signals``),
but the kink's impulse reaches well beyond through the rows' filters: on the concealed
study's drive with ``b`` = 1 um the baseline's residual is 4x the floor 150-200
samples after a restart.  The term is one column, ``J_gap*e''`` (the motor's inertia
seen across the gap: ``J_gap`` is the model's ``J`` when the term is right), with
``e`` built from the measured motion (:func:`gap_path`):

* a dwell is a run of samples whose filtered speed is within ``LOOSE`` (10) times the
  direction threshold, runs closer than the restart's window ``w`` (two Butterworth
  periods) merged;
* the restart ``t2`` and velocity ``v2``: a parabola through the raw position over
  ``w`` samples just after it (first placed from the filtered motion ``w`` samples after
  the run), extrapolated back to the position the load stood at (the filtered motion
  alone rings after the kink: its ``v2`` was 10 % off);
* across the dwell ``e`` is the cubic (Hermite) from ``(s_before*b, e' = 0)`` at the
  run's start to ``(s_after*b, e' = v2)`` at ``t2``, constant after;
* the motor's reversal ``t1``: the load's deceleration before the run extrapolated to
  zero speed.

``e`` is linear in ``b`` (``e = b*E1 + E2``), but the rows hardly see ``E1`` (the dwell's
interior is kept out): a least-squares ``b`` was 0.46 um for 1 um (with a first, cruder
restart).  The dwell's
*duration* does: the motor leaves the gap's edge at rest at ``t1`` and crosses ``2*b``
by ``t2``, where it moves at ``v2``; under a roughly constant force ``2*b = v2*(t2 -
t1)/2``.  So the half-gap is **fitted on the dwells** of the training part, the median
of ``|v2|*(t2 - t1)/4`` over its reversals (2.00 um for 2 um on an open-loop swing;
0.995 and 2.15 um for 1 and 2 um on the concealed study's closed loop), a one-point
grid; the column's coefficient is fitted on the
rows and the term is judged by the held-out rows like any other
(``servo.diagnose.select``).  Viscous and stiffness parts of ``e`` (``B*e'``,
``K*e``) are left out: ``K*b*s`` is a Coulomb column (a fitted ``Fc`` carries it), the
rest is within the kept-out rows.

A model that holds a sensor lag builds the column on the lag-corrected motion
(``servo.diagnose.sensor_lag.corrects``: the drive's play acts before the low-pass);
the restart's parabola then still reads the raw, lagged position (the two together are
untested).  Not cancellable by a force on the motor: see ``not_cancellable``.
"""
from __future__ import annotations

import math
import weakref

import numpy as np

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, Term

#: a dwell: the filtered speed within this many direction thresholds (the load's
#: restart is a velocity step hundreds of thresholds high; the noise crosses one)
LOOSE = 10.0
#: the last signals object's dwells (:func:`_dwells`): a weak reference to it, and them
_LAST: list = [None, None]
#: the refinement's interval around the dwells' half-gap, as a factor (held: 1e-6)
HELD = 1.0 + 1e-6
#: reversals a training part needs for its half-gap
MIN_REVERSALS = 3


def _restart(k: int, dx: float, v: float, a: float, dt: float) -> float:
    """The sample (fractional) at which a motion at ``dx`` (m) from where it stood, with
    velocity ``v`` and acceleration ``a`` at sample ``k``, left it:
    ``dx = v*h - a*h^2/2``, ``h`` the time since (``k`` itself when it does not move)."""
    if v == 0.0:
        return float(k)
    disc = v * v - 2.0 * a * dx
    h = (v - math.copysign(math.sqrt(disc), v)) / a if a != 0.0 and disc > 0.0 else dx / v
    if not h >= 0.0:
        h = max(dx / v, 0.0)
    return k - h / dt


def _dwells(sig) -> list[tuple]:
    """:func:`find_dwells` of ``sig``, computed once per signals object (every round of a
    diagnosis asks for its grid)."""
    ref, held = _LAST
    if ref is None or ref() is not sig:
        held = find_dwells(sig)
        _LAST[:] = [weakref.ref(sig), held]
    return held


def find_dwells(sig) -> list[tuple]:
    """The dwells of the measured motion ``sig`` (:class:`~servo.diagnose.signals.Signals`):
    ``(i1, ka, t1, t2, s_before, s_after, v2)`` each, ``i1`` the run's first sample,
    ``ka`` the sample the restart is read at, ``t1``/``t2`` (fractional samples) the
    motor's reversal and the load's restart, ``v2`` (m/s) its velocity then."""
    vf, xf, af, x, dt = sig.vf, sig.xf, sig.af, sig.x, sig.dt
    n = vf.size
    fs = 1.0 / dt
    w = int(math.ceil(2.0 * fs / sig.settings.cutoff(fs)))
    still = np.abs(vf) <= LOOSE * sig.v_threshold
    edge = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    runs: list[list[int]] = []
    for a, b in zip(np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)):
        if runs and a - runs[-1][1] < w:
            runs[-1][1] = int(b)
        else:
            runs.append([int(a), int(b)])
    hk = np.arange(w + 1) * dt
    fit = np.linalg.pinv(np.column_stack([hk * hk, hk, np.ones(w + 1)]))  # least-squares parabola
    out = []
    for i1, i2 in runs:
        ka, kb = i2 + w, i1 - w
        if kb < 0 or ka + 2 * w >= n:
            continue
        va, aa, vb, ab = float(vf[ka]), float(af[ka]), float(vf[kb]), float(af[kb])
        if va == 0.0 or vb == 0.0:
            continue
        level = float(np.median(x[i1:i2]))  # where the load stood
        # the restart, first from the filtered motion at ka (its acceleration held) ...
        t2 = _restart(ka, float(xf[ka]) - level, va, aa, dt)
        # ... then from a parabola through the raw position just after it: the filter
        # rings after the kink (read at ka alone, v2 was 10 % off on an open-loop swing)
        k0 = min(max(int(math.ceil(t2)) + 2, ka - w), n - w - 1)
        c2, c1, c0 = fit @ (x[k0 : k0 + w + 1] - level)
        t2 = min(max(_restart(k0, c0, c1, 2.0 * c2, dt), float(i1)), float(ka))
        v2 = c1 + 2.0 * c2 * (t2 - k0) * dt
        if v2 == 0.0:
            continue
        hb = -vb / ab if ab * vb < 0.0 else 0.0  # the deceleration before it reaches zero speed
        t1 = min(max(kb + hb / dt, float(kb)), t2)
        out.append((i1, ka, t1, t2, math.copysign(1.0, vb), math.copysign(1.0, v2), v2))
    return out


def gap_path(sig, b: float, events: list | None = None) -> np.ndarray:
    """The motor's place in the gap ``e`` (n,) (m) for a half-gap ``b``: ``x = y + e``
    (module doc)."""
    events = _dwells(sig) if events is None else events
    e = b * np.sign(sig.vf)
    for i1, ka, t1, t2, sb, sa, v2 in events:
        start = i1 - 1
        k = np.arange(start, ka + 1)
        span = max(t2 - start, 1e-9)
        tau = np.clip((k - start) / span, 0.0, 1.0)
        e[k] = b * ((2 * tau**3 - 3 * tau**2 + 1) * sb + (3 * tau**2 - 2 * tau**3) * sa) + (tau**3 - tau**2) * v2 * span * sig.dt
    return e


def half_gap(sig, samples: np.ndarray | None = None) -> tuple[float, int]:
    """The half-gap (m) the reversals' dwells imply, the median of ``|v2|*(t2 - t1)/4``
    over the reversals whose restart lies in ``samples`` ((n,) bool; None: all), and how
    many there were."""
    ests = [abs(v2) * (t2 - t1) * sig.dt / 4.0 for i1, ka, t1, t2, sb, sa, v2 in _dwells(sig)
            if sa != sb and (samples is None or samples[ka])]  # fmt: skip
    return (float(np.median(ests)) if ests else 0.0), len(ests)


class Backlash(Term):
    name, coefs, thetas = "backlash", ("J_gap",), ("half_gap",)
    units = {"J_gap": "F*s^2/m", "half_gap": "m"}
    doc = ("a play of half-gap b between the motor and the load the sensor reads: the motor's inertia J_gap times "
           "its acceleration across the gap, e'' with x = y + e (the half-gap from the dwells at reversals)")  # fmt: skip
    POSITIVE = {"J_gap": "the gap's column enters with the sign of an inertia: a negative one is no motor crossing it"}

    def full(self, d, theta, u_eff):
        s = d.sig
        e = s.butter(gap_path(s, float(theta["half_gap"])))
        out = np.empty_like(e)  # the second difference, as the rows' acceleration
        out[1:-1] = (e[2:] - 2.0 * e[1:-1] + e[:-2]) / (s.dt * s.dt)
        out[0], out[-1] = out[1], out[-2]
        return out

    def grid(self, d, model):
        """One half-gap: the training part's dwells' (:func:`half_gap`); none (not
        testable) with fewer than :data:`MIN_REVERSALS` reversals."""
        b, k = half_gap(d.sig, getattr(d, "train_samples", None))
        return [{"half_gap": b}] if k >= MIN_REVERSALS and b > 0 else []

    def bounds(self, d, model):
        """The dwells' half-gap, held: the rows hardly see it (module doc), and left to
        them the refinement ran to the edge of any interval (+10 % of 2 um)."""
        b = self.grid(d, model)
        b = b[0]["half_gap"] if b else 1.0
        return {"half_gap": (b / HELD, b * HELD, True)}

    def implausible(self, params):
        if params["J_gap"] <= 0:
            return f"the best fit has J_gap = {params['J_gap']:.3g} <= 0: no inertia crosses the gap"
        return ""


class BacklashDrive(DriveMap):
    """The backlash term in the simulated drive's ``[drive]`` section: its half-gap (the
    coefficient, the motor's inertia, is the drive's ``J``)."""

    name = "backlash"
    absent = {"backlash_half_gap": 0.0}

    def to_drive(self, P, fit):
        return {"backlash_half_gap": max(P[self.name]["half_gap"], 0.0)}

    def from_drive(self, d):
        return [({"half_gap": d.backlash_half_gap}, (d.J,))] if d.backlash_half_gap > 0 else []


#: sizes: the half-gap, from 0.1 to 5 um (the study's strokes are +-1.3 mm, its sensor
#: noise 1 nm)
_STUDY = Concealment("backlash", "m", "half-gap between motor and load", (1e-7, 2e-7, 5e-7, 1e-6, 2e-6), 2e-6,
                     fields=lambda size: {"backlash_half_gap": size})  # fmt: skip


EFFECT = Effect(
    "backlash", "play between motor and load: the sensor reads a load that follows the motor through a gap",
    drive=dict(backlash_half_gap=P(0.0, "m", "half the play between the motor and the load the sensor reads (0: "
                                   "none)", 0.0)),
    plant=lambda d, dt: {"backlash": d.backlash_half_gap},
    term=Backlash(),
    drive_map=BacklashDrive(),
    study=_STUDY,
    not_cancellable="a play between the motor and the measured load is not a force on the motor: no feedforward "
                    "moves the load across the gap, and a loop closed on the load hunts in it; measure the motor's "
                    "position too (close the loop on the motor, the load's sensor in an outer loop), or preload "
                    "the joint",
    # the short-horizon simulation starts the motor at the measured position: the load's
    # place in the gap is a state it does not hold, so the play is off there
    simulated=lambda d, sim: {"backlash_half_gap": 0.0},
)  # fmt: skip

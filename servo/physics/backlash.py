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

* a dwell is a run of samples at which the *raw* position stands still (its slope over
  five samples within four noise widths, :func:`standing`), each run on its own: under
  a PRBS or a chirp's fast end the load stands, moves for ten samples and stands
  again, and the filtered speed (the first version's) merged such bursts into one run
  with a wrong restart and wrong directions (the path 0.4-0.9 half-gaps off);
* the directions before and after: the load's whole move from the previous dwell and to
  the next (it does not reverse between dwells), not the sign of a restart too slow to
  read;
* the restart ``t2`` and velocity ``v2``: a parabola through the raw position over the
  12 samples after the run (fewer where the next dwell begins, the kink's samples
  skipped), extrapolated back to the position the load stood at;
* across the dwell the motor moves from rest at ``t_s`` to ``t2``: under a steady force
  a crossing of ``2*b`` takes ``4*b/|v2|``, so ``t_s = max(t1, t2 - 4*b/|v2|)`` and
  ``e`` is the cubic (Hermite) from ``(s_before*b, e' = 0)`` at ``t_s`` to
  ``(s_after*b, e' = v2)`` at ``t2`` (a parabola when the force is steady), constant
  after; a motor that turned back inside the gap (``s_after == s_before``) goes no
  deeper than the gap.

``e`` is linear in ``b`` only outside the dwells, and the rows hardly see ``E1`` there
(the dwell's interior is kept out: a least-squares ``b`` was 0.46 um for 1 um).  The
dwell's *duration* does: the motor leaves the gap's edge at rest at ``t1`` and crosses
``2*b`` by ``t2``, where it moves at ``v2``; under a steady force ``2*b = v2*(t2 -
t1)/2``, the median over the training part's reversals (:func:`half_gap`; 1.84 um for
2 um on an open-loop swing).  The force is not steady under a PRBS or an open-loop
drive (the estimate was 0.7-2 times the truth on the proving ground), so the grid is
five half-gaps from half to twice it, chosen inside the cross-validation's folds and
refined on the training rows; the column's coefficient is fitted on the rows and the
term is judged by the held-out rows like any other (``servo.diagnose.select``).
Viscous and stiffness parts of ``e`` (``B*e'``, ``K*e``) are left out: ``K*b*s`` is a
Coulomb column (a fitted ``Fc`` carries it), the rest is within the kept-out rows.

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
from servo.physics.base import Concealment, DriveMap, Effect, Judging, Term

#: a dwell: the filtered speed within this many direction thresholds (the load's
#: restart is a velocity step hundreds of thresholds high; the noise crosses one)
LOOSE = 10.0
#: the last signals object's dwells (:func:`_dwells`): a weak reference to it, and them
_LAST: list = [None, None]
#: the half-gaps tried: the dwells' estimate times and over this factor (:meth:`Backlash.grid`)
SPREAD = 2.0
#: half-gaps in that range, geometric
GRID = 5
#: reversals a training part needs for its half-gap
MIN_REVERSALS = 3
#: samples of the centred line whose slope says the load stands (:func:`standing`)
SLOPE_SPAN = 5
#: the load stands where that slope is within this many of its noise standard deviations
STILL = 4.0
#: a dwell stands at least this many samples
MIN_RUN = 3
#: samples of the parabola through the raw position after a restart (fewer where the next dwell begins)
PARABOLA = 12


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


def standing(x: np.ndarray, noise_x: float, dt: float) -> np.ndarray:
    """Samples (n,) bool at which the raw position ``x`` (n,) (m) stands still: its slope
    over :data:`SLOPE_SPAN` samples (a centred least-squares line) within :data:`STILL`
    standard deviations of what a position noise of std ``noise_x`` (m) gives it.  The
    load stands still across a dwell to the sample, while a moving arm at the speeds of
    a reversal's restart covers hundreds of noise widths a sample."""
    h = SLOPE_SPAN // 2
    j = np.arange(-h, h + 1, dtype=float)
    slope = np.convolve(x, j[::-1] / (np.sum(j * j) * dt), mode="same")
    sd = max(noise_x, 1e-300) / (math.sqrt(np.sum(j * j)) * dt)
    out = np.abs(slope) <= STILL * sd
    out[:h], out[x.size - h :] = False, False
    return out


def find_dwells(sig) -> list[tuple]:
    """The dwells of the measured motion ``sig`` (:class:`~servo.diagnose.signals.Signals`):
    ``(i1, ka, t1, t2, s_before, s_after, v2)`` each, ``i1`` the run's first sample,
    ``ka`` the sample the path's dwell ends at, ``t1``/``t2`` (fractional samples) the
    load's stop (the motor's reversal) and its restart, ``v2`` (m/s) its velocity then.

    A dwell is a run of :func:`standing` samples of the raw position (at least
    :data:`MIN_RUN`; gaps of one sample closed), each read on its own: under a PRBS or
    a chirp's fast end the load stands, moves for ten samples and stands again, and the
    filtered speed the rows use merges such a burst into one run whose restart and
    directions are wrong (the estimated path was 0.4-0.9 half-gaps off on them)."""
    x, dt = sig.x, sig.dt
    n = x.size
    still = standing(x, sig.noise_x, dt)
    edge = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    runs: list[list[int]] = []
    for a, b in zip(np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)):
        if runs and a - runs[-1][1] <= 1:
            runs[-1][1] = int(b)
        else:
            runs.append([int(a), int(b)])
    runs = [r for r in runs if r[1] - r[0] >= MIN_RUN]
    out = []
    for j, (i1, i2) in enumerate(runs):
        prev_end = runs[j - 1][1] if j else 0
        next_start = runs[j + 1][0] if j + 1 < len(runs) else n
        # the restart: a parabola through the raw position after the run, clear of the
        # kink (the run's slope window reaches a sample past it) and of the next dwell,
        # extrapolated back to where the load stood
        k0 = i2 + SLOPE_SPAN // 2
        m = min(PARABOLA, next_start - k0 - 1)
        if m < 4 or i1 < 1:
            continue
        level = float(np.median(x[i1:i2]))
        hk = np.arange(m + 1) * dt
        c2, c1, c0 = np.polyfit(hk, x[k0 : k0 + m + 1] - level, 2)
        t2 = min(max(_restart(k0, c0, c1, 2.0 * c2, dt), float(i1)), float(k0))
        v2 = c1 + 2.0 * c2 * (t2 - k0) * dt
        # the directions: the load's whole move from the previous dwell and to the next
        # (it does not reverse between dwells); a restart too slow for the parabola's
        # sign (a motor that barely came back) keeps its size, with that direction
        sb = math.copysign(1.0, x[i1] - x[prev_end - 1 if j else 0])
        sa = math.copysign(1.0, x[next_start - 1] - x[i2 - 1])
        if x[i1] == x[prev_end - 1 if j else 0] or x[next_start - 1] == x[i2 - 1]:
            continue
        v2 = math.copysign(abs(v2), sa)
        ka = min(int(math.ceil(t2)) + 1, n - 1)
        out.append((i1, ka, float(i1), t2, sb, sa, v2))
    return out


def gap_path(sig, b: float, events: list | None = None) -> np.ndarray:
    """The motor's place in the gap ``e`` (n,) (m) for a half-gap ``b``: ``x = y + e``
    (module doc).  Between dwells the load is pushed: ``e`` is ``b`` times the direction
    the previous dwell's restart set (``sign(vf)`` on a stretch where the filtered speed
    says otherwise, a reversal no dwell marks).  Across a dwell the motor moves from rest
    at ``t_s`` to the restart at ``t2`` with the velocity ``v2``: a crossing from
    ``s_before*b`` to ``s_after*b`` takes ``4*b/|v2|`` under a steady force, so
    ``t_s = max(t1, t2 - 4*b/|v2|)``; a motor that turned back inside the gap
    (``s_after == s_before``) goes no deeper than the gap."""
    events = _dwells(sig) if events is None else events
    loose = np.abs(sig.vf) > LOOSE * sig.v_threshold
    sv = np.sign(sig.vf)
    e = b * sv
    bounds = [0] + [ev[1] + 1 for ev in events]
    for j, ev in enumerate(events):
        lo, hi = bounds[j], ev[0]
        s = ev[4]
        seg = slice(lo, hi)
        if not np.any(loose[seg] & (sv[seg] != s)):
            e[seg] = b * s
    if events:
        lo, s = events[-1][1] + 1, events[-1][5]
        if not np.any(loose[lo:] & (sv[lo:] != s)):
            e[lo:] = b * s
    for i1, ka, t1, t2, sb, sa, v2 in events:
        T = 4.0 * b / abs(v2) / sig.dt if sa != sb else 27.0 * 2.0 * b / (4.0 * abs(v2)) / sig.dt
        ts = max(t1, t2 - T)
        k = np.arange(i1, ka + 1)
        span = max(t2 - ts, 1e-9)
        tau = np.clip((k - ts) / span, 0.0, 1.0)
        e[k] = b * ((2 * tau**3 - 3 * tau**2 + 1) * sb + (3 * tau**2 - 2 * tau**3) * sa) + (tau**3 - tau**2) * v2 * span * sig.dt
    return e


def half_gap(sig, samples: np.ndarray | None = None) -> tuple[float, int]:
    """The half-gap (m) the reversals' dwells imply, the median of ``|v2|*(t2 - t1)/4``
    over the reversals whose restart lies in ``samples`` ((n,) bool; None: all), and how
    many there were."""
    ests = [abs(v2) * (t2 - t1) * sig.dt / 4.0 for i1, ka, t1, t2, sb, sa, v2 in _dwells(sig)
            if sa != sb and (samples is None or samples[ka])]  # fmt: skip
    return (float(np.median(ests)) if ests else 0.0), len(ests)


class GapJudging(Judging):
    """An inertia crosses the gap: ``J_gap > 0``."""

    def implausible(self, params):
        if params["J_gap"] <= 0:
            return f"the best fit has J_gap = {params['J_gap']:.3g} <= 0: no inertia crosses the gap"
        return ""


class Backlash(Term):
    name, coefs, thetas = "backlash", ("J_gap",), ("half_gap",)
    units = {"J_gap": "F*s^2/m", "half_gap": "m"}
    doc = ("a play of half-gap b between the motor and the load the sensor reads: the motor's inertia J_gap times "
           "its acceleration across the gap, e'' with x = y + e (the half-gap from the dwells at reversals)")  # fmt: skip
    judging = GapJudging(
        positive={"J_gap": "the gap's column enters with the sign of an inertia: a negative one is no motor crossing it"},
        rests=("the sensor's load stands across each dwell while the motor crosses the gap, whatever the friction: "
               "its intervals at rest are the play's"))  # fmt: skip

    def full(self, d, theta, u_eff):
        s = d.sig
        e = s.butter(gap_path(s, float(theta["half_gap"])))
        out = np.empty_like(e)  # the second difference, as the rows' acceleration
        out[1:-1] = (e[2:] - 2.0 * e[1:-1] + e[:-2]) / (s.dt * s.dt)
        out[0], out[-1] = out[1], out[-2]
        return out

    def grid(self, d, model):
        """Half-gaps around the training part's dwells' (:func:`half_gap`), a factor
        :data:`SPREAD` either side (:data:`GRID` of them): the dwells' estimate assumes a
        steady force across the gap, off by a factor 0.7-2 under a PRBS or an open-loop
        drive, and the cleaner path of the restarts lets the rows tell; none (not
        testable) with fewer than :data:`MIN_REVERSALS` reversals."""
        b, k = half_gap(d.sig, getattr(d, "train_samples", None))
        if k < MIN_REVERSALS or not b > 0:
            return []
        return [{"half_gap": float(v)} for v in b * np.geomspace(1.0 / SPREAD, SPREAD, GRID)]

    def bounds(self, d, model):
        """The grid's range, refined on the training rows."""
        b, _ = half_gap(d.sig, getattr(d, "train_samples", None))
        b = b if b > 0 else 1.0
        return {"half_gap": (b / SPREAD, b * SPREAD, True)}

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

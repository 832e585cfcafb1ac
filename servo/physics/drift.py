"""A slowly wandering force offset (thermal drift, a bias that wanders): ``h0 + drift(t)``.

The effect's diagnosis term, drive mapping and documentation entry
(:class:`~servo.physics.base.Effect`).

**The columns.**  ``drift(t)`` is piecewise linear in time: :data:`KNOTS` hat functions
whose knots stand ``time_scale`` apart, counted back from the end of the training part
(the last knot one time scale before its last sample); before the earliest knot's left
neighbour the drift is 0 (the offset ``h0`` carries the level there) and after the last
knot it holds the level it reached.  The last knot stands back from the end so that the
cross-validation's last block, left out, is forecast as the test part is (the level
held from the knots its neighbours determine), not extrapolated along a hat whose
coefficient only that block's rows could set.  The coefficients ``d1 .. d6`` are the drift at the knots, earliest first, in
the force unit; ``time_scale`` (s) is a nonlinear parameter (a grid of three from a
fourteenth to a seventh of the training span, refined between), so at the largest time
scale the knots cover the whole training part.  Reported beside them: ``size`` the
drift's peak-to-peak over its knots and ``end_level`` where it stands at the end.

**Why it holds after the training part.**  The test part lies later in time than the
training part (:mod:`servo.diagnose.select` holds out the recording's last quarter);
no smooth basis fitted on the past says where a random wander goes next, so the term
predicts the test part with the level the drift reached at the end of training (the
persistence forecast).  That forecast is no proof: the proving ground's drifts wander
on through the last quarter, and it failed there on half of them.  The held-out proof
(:meth:`Drift.proven`) therefore has the drift's course through the test part
cross-fitted across the motion's direction, fitted on the rows moving one way and
judged on those moving the other, every physical coefficient as trained;
``servo.diagnose.job`` asks it to remove a material share of the residual there.  A
drift does not depend on the direction; a force that switches on with the direction
in it (a hysteresis from some time on), which a course fitted in time follows as a
level, is predicted with the wrong sign.
Inside the training part the blocked cross-validation interpolates a left-out block
between its neighbours' knots.

**The verdict's checks follow it** (:meth:`Drift.followed`).  The verdict's held-out
residual of a model with a drift has the drift's course fitted to it over the training
and test rows together (the term's hats and knots ``time_scale`` apart after them, a
handful of coefficients against thousands of rows), every physical coefficient as
cross-validated or trained; the report says so.

**The simulated drive does not carry it.**  Its plant (:mod:`kernels.plant`) has no
clock: a drift is a record of this recording's past, not a property of the drive to
replay.  The fitted model's ``[drive]`` section holds the offset the drift reached at
the end of training (``h0 + d6``), which is what the short-horizon simulation of the
held-out part and ``final_model.toml`` use, and what ``servo compensate`` cancels as
the bias (eq. 9); the wander itself is :attr:`Effect.not_cancellable`.  No concealment
either: the concealed-effect study (:mod:`servo.diagnose.concealed`) hides effects in
the simulated drive, which has no drift; the proving ground's ``drift`` family
(``studies/proving/``) is its test bed.
"""
from __future__ import annotations

import numpy as np

from servo.physics.base import DriveMap, Effect, Judging, Search, Term, geom

#: hat functions of the drift (its coefficients ``d1 .. d6``)
KNOTS = 6
#: the time-scale grid: from the training span / (KNOTS * SPAN_RANGE) to span / KNOTS
SPAN_RANGE = 2.0


def _span(d) -> tuple[float, float]:
    """``(first, last)`` full-rate time (s) of the training part of the design ``d``."""
    t = d.sig.t
    last = int(np.flatnonzero(d.train_samples)[-1])
    return float(t[0]), float(t[last])


def row_times(d) -> np.ndarray:
    """The rows' instants (m,) in s: the time itself through the rows' decimation (a
    zero-phase filter with odd padding returns a linear function unchanged)."""
    return d.sig.rows(d.sig.t)


def hats(t: np.ndarray, t_end: float, time_scale: float) -> np.ndarray:
    """The drift's columns (n, :data:`KNOTS`) at times ``t`` (s): hat functions with
    knots ``t_end - j*time_scale`` (``j = KNOTS .. 1``, earliest first), the drift 0
    up to ``t_end - (KNOTS+1)*time_scale`` and held at the last knot's level after
    ``t_end - time_scale`` (module doc)."""
    last = t_end - time_scale
    s = (np.minimum(t, last) - last) / time_scale + KNOTS  # knots at 1 .. KNOTS, 0 the drift's zero
    return _tents(s, np.arange(1, KNOTS + 1))


def _tents(s: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """``max(0, 1 - |s - k|)`` for each knot ``k``, (n, len(knots)), built column by
    column in place (a full-rate recording's temporaries of the whole block cost a
    diagnosis its memory budget)."""
    H = np.empty((s.size, knots.size))
    for j, k in enumerate(knots):
        col = H[:, j]
        np.subtract(s, k, out=col)
        np.abs(col, out=col)
        np.subtract(1.0, col, out=col)
        np.maximum(col, 0.0, out=col)
    return H


class DriftJudging(Judging):
    """A drift is a record of the recording's past: its course through the test part is
    fitted there (the verdict) and cross-fitted across the motion's direction (the proof)."""

    def followed(self, d, theta, r, rows):
        """The held-out residual ``r`` (m,) with the drift's course fitted to it over the
        training part's usable rows and the test ``rows`` together: the term's own hats
        (:meth:`Drift.rows`; the cross-validated residual interpolates a left-out block's
        drift from its neighbours' knots) and its course after them (:meth:`Drift._course`,
        whose first hat reaches back over the training part's last time scale, where
        the term holds its level).  A handful of coefficients against thousands of rows;
        every physical coefficient as cross-validated or trained."""
        fit = (d.train_valid | rows) & np.isfinite(r)
        M = np.hstack([self.term.rows(d, theta, None), self.term._course(d, theta)])
        if fit.sum() <= 2 * M.shape[1]:
            return r
        c, *_ = np.linalg.lstsq(M[fit], r[fit], rcond=None)
        out = r.copy()
        out[fit] = r[fit] - M[fit] @ c
        return out

    def proven(self, d, theta, r, rows):
        """The held-out proof's residual: the course (:meth:`Drift._course`) cross-fitted on the
        test ``rows`` across the motion's direction, fitted on the rows moving one way
        (the filtered speed's sign at the row) and judged on those moving the other way,
        and the other way round.  A drift is a force whatever the motion does, so the
        course one direction's rows set predicts the other's, interleaved with them
        through the whole test part; a force that switches on with the motion's
        direction in it (a hysteresis element from some time on, which a smooth course
        otherwise follows as a level) is predicted with the wrong sign, and a null's
        residual gains nothing.  The persistence forecast alone failed the proof on half
        the proving ground's drifts (the drift wanders on through the last quarter);
        stretches of the test part in time, the version before, were confirmed by such
        an onset once their edges stood on the knots."""
        Z = self.term._course(d, theta)
        idx = np.flatnonzero(rows)
        if not Z.shape[1] or idx.size < 2 * Z.shape[1]:
            return r
        up = d.sig.v_rows[idx] >= 0.0
        out = r.copy()
        for fit_on in (up, ~up):
            if not fit_on.any() or fit_on.all():
                return r
            c, *_ = np.linalg.lstsq(Z[idx[fit_on]], r[idx[fit_on]], rcond=None)
            judged = idx[~fit_on]
            out[judged] = r[judged] - Z[judged] @ c
        return out


class Drift(Term):
    name, thetas = "drift", ("time_scale",)
    coefs = tuple(f"d{j}" for j in range(1, KNOTS + 1))
    units = {"time_scale": "s", "size": "F", "end_level": "F", **{c: "F" for c in coefs}}
    doc = "a force offset wandering in time: piecewise linear, knots time_scale apart (held after training)"
    #: needs the offset (the level before the drift's first knot); not gated: it is a
    #: function of time already
    search = Search(requires=("offset",), gated=False)
    judging = DriftJudging(follows="the drift's course is fitted to it, since a wander cannot be forecast")

    def full(self, d, theta, u_eff):
        _, t_end = _span(d)
        return hats(d.sig.t, t_end, theta["time_scale"])

    def rows(self, d, theta, u_eff):
        """The rows (m, :data:`KNOTS`): the hat functions at the rows' instants
        (:func:`row_times`).  The rows' zero-phase low-pass leaves a function linear in
        time unchanged, so a hat's rows differ from its filtered samples only within
        the filter's reach (milliseconds) of a knot, against knots at least
        ``time_scale`` (a tenth of a second and more) apart; filtering each of the
        KNOTS columns of every time scale at full rate cost a 1e6-sample diagnosis
        most of its time."""
        _, t_end = _span(d)
        return hats(row_times(d), t_end, theta["time_scale"])

    def grid(self, d, model):
        t0, t_end = _span(d)
        hi = (t_end - t0) / (KNOTS + 1)
        return [{"time_scale": float(v)} for v in geom(hi / SPAN_RANGE, hi, 3.5)]

    def bounds(self, d, model):
        t0, t_end = _span(d)
        hi = (t_end - t0) / (KNOTS + 1)
        return {"time_scale": (hi / SPAN_RANGE, hi, True)}

    def _course(self, d, theta) -> np.ndarray:
        """The drift's course after the training part (m, k) at the rows' instants: hat
        functions ``time_scale`` apart from the training part's last knot (its level
        already in a residual) to the end, the last holding its level."""
        _, t_end = _span(d)
        tau = theta["time_scale"]
        last = t_end - tau  # the training part's last knot
        k = np.arange(1, int(np.ceil((d.sig.t[-1] - last) / tau)) + 1)
        if not k.size:
            return np.zeros((d.sig.keep.size, 0))
        sr = (np.maximum(row_times(d), last) - last) / tau
        Z = _tents(sr, k)
        Z[:, -1] = np.clip(sr - (k[-1] - 1), 0.0, 1.0)  # the last knot holds its level to the end
        return Z

    def physical(self, theta, coef):
        c = np.asarray(coef, dtype=float)
        path = np.concatenate([[0.0], c])  # the drift at the knots, from its zero
        return {"size": float(np.ptp(path)), "time_scale": float(theta["time_scale"]), "end_level": float(c[-1]),
                **{k: float(v) for k, v in zip(self.coefs, c)}}  # fmt: skip

    def from_physical(self, p):
        return {"time_scale": p["time_scale"]}, tuple(p[k] for k in self.coefs)


class DriftDrive(DriveMap):
    """The drift in the ``[drive]`` section: the offset it reached at the end of the
    training part (the drive has no clock, module doc)."""

    name = "drift"

    def to_drive(self, P, fit):
        return {"h0": P.get("offset", {}).get("h0", 0.0) + P[self.name]["end_level"]}


EFFECT = Effect(
    "drift", "a force offset wandering in time (thermal drift, a wandering bias): size and time scale",
    term=Drift(),
    drive_map=DriftDrive(),
    not_cancellable=("a wandering offset goes on after the recording: a static term cancels the level it reached "
                     "(final_model.toml's h0 holds it, cancelled with the bias of eq. 9), not its future course; "
                     "an integrator in the loop follows it"),
)  # fmt: skip

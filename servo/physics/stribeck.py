"""Stribeck friction: a breakaway level ``Fs`` above the sliding ``Fc`` at low speed.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, Judging, Search, SignalPath, Term, geom, valid_speed

#: the Stribeck curve's shape exponent ``delta`` of ``exp(-|x'/vs|^delta)``: 2 the
#: paper's Gaussian curve, 1 the exponential one, below 1 a cusp at rest; the grid's
#: values and the refinement's bounds (a Lorentzian ``1/(1 + r^2)`` lies near 1.5)
SHAPES = (0.6, 1.0, 2.0)
SHAPE_BOUNDS = (0.4, 3.0)
#: the shape the drive kernel and the compensator hold (Gaussian), and a term's shape
#: when none is given (a breakaway found at rest, a drive's fields)
GAUSSIAN = 2.0
#: bristle deflections at rest on the grid (with the Gaussian shape, LuGre's), per decade,
#: up to this fraction of the stroke
LENGTHS_PER_DECADE, LENGTH_MAX = 1.0, 0.01


#: a deflection (a Dahl length, a bristle's) below this many std of the position noise is
#: not resolved: the noise moves the filtered position by a tenth of it at every reversal
RESOLVE_Z = 10.0


@lru_cache(maxsize=16)
def _butter_impulse(order: int, wn: float) -> np.ndarray:
    """(N,) the zero-phase Butterworth's impulse response (``wn`` of Nyquist)."""
    from scipy import signal

    b, a = signal.butter(order, wn)
    n = int(40 / wn) + 101
    z = np.zeros(2 * n + 1)
    z[n] = 1.0
    return signal.filtfilt(b, a, z, padlen=3 * order)


def resolvable_length(sig) -> float:
    """The smallest deflection (m) the position resolves: :data:`RESOLVE_Z` times the
    larger of ``sig.noise_x`` and the std of the noise spectrum ``sig.noise`` through the
    position's Butterworth.  A low-frequency (low-pass, pink) noise passes the filter
    whole, while ``noise_x``, its white equivalent through the rows' acceleration, reads
    a fraction of it (a fourth to a seventh on the proving ground's low-pass nulls, where
    a Dahl length of 2.4 nm, two noise std, was named on a null)."""
    s = float(sig.noise_x)
    spec = getattr(sig, "noise", None)
    if spec is not None:
        fs = 1.0 / sig.dt
        h = _butter_impulse(int(sig.settings.butter_order), float(sig.settings.cutoff(fs) / (fs / 2)))
        s = max(s, float(spec.std_through(h, fs)))
    return RESOLVE_Z * s


def curve(v: np.ndarray, vs: float, delta: float = GAUSSIAN) -> np.ndarray:
    """The Stribeck curve's fall with speed, ``exp(-|v/vs|^delta)`` (dimensionless, as ``v``)."""
    return np.exp(-(np.abs(v / vs) ** delta))


#: the speeds (in Stribeck velocities) over which the Gaussian stand-in matches a curve
STAND_IN_SPAN = 4.0


@lru_cache(maxsize=64)
def gaussian_stand_in(delta: float) -> tuple[float, float]:
    """``(a, b)``: the Gaussian ``a*exp(-(r/b)^2)`` nearest ``exp(-r^delta)`` in least
    squares over ``r = v/vs`` in ``[0, STAND_IN_SPAN]`` (1, 1 for the Gaussian itself): what a
    drive or compensator that holds only the Gaussian curve takes for another shape,
    ``Fs = Fc + a*dFs`` and ``vs*b``."""
    if delta == GAUSSIAN:
        return 1.0, 1.0
    r = np.linspace(0.0, STAND_IN_SPAN, 801)
    y = curve(r, 1.0, delta)

    def fit(log_b):
        g = np.exp(-((r / np.exp(log_b)) ** 2))
        a = float(g @ y / (g @ g))
        return float(np.sum((y - a * g) ** 2)), a

    from scipy import optimize  # here, not at import: reading a config imports no scipy

    res = optimize.minimize_scalar(lambda z: fit(z)[0], bounds=(-3.0, 3.0), method="bounded", options={"xatol": 1e-6})
    return fit(res.x)[1], float(np.exp(res.x))


def bristle_trace(d, vs: float, delta: float, length: float) -> np.ndarray:
    """The normalised force of a Stribeck rise held by bristles (``kernels.stribeck``)
    along the design's filtered motion, (n,)."""
    from kernels.stribeck import stribeck_bristle_trace

    out = np.empty(d.sig.n)
    stribeck_bristle_trace(d.sig.xf, d.sig.vf, float(vs), float(delta), float(length), out)
    return out


def bristles(P: dict) -> tuple[float, float] | None:
    """``(dFs, length)`` of a fitted Stribeck rise held by bristles in a model without a
    Dahl element, None otherwise: the simulated drive, whose kernel holds no bristle
    term, runs it as a Dahl element of level ``dFs`` and that length with the Coulomb
    level lowered by ``dFs`` under the same Stribeck rise (``Fc - dFs + dFs*phi(v)`` plus
    the saturated element's ``dFs``: the steady state ``Fc + dFs*phi(v)``, and the
    bristles' pre-sliding at a reversal, where ``phi`` is 1)."""
    st = P.get("stribeck_friction") or {}
    if not (st.get("stribeck_length", 0.0) > 0 and st.get("dFs", 0.0) > 0):
        return None
    if P.get("hysteresis"):  # the model's own Dahl element carries the pre-sliding
        return None
    return float(st["dFs"]), float(st["stribeck_length"])


class StribeckSearch(Search):
    """The bristles' variants ranked coarsely before their exact columns; a grid point
    without bristles keeps none in the refinement."""

    def coarse_ranks(self, theta):
        """The bristles' variants (one shape, the Gaussian) are ranked among themselves by
        their traces over the rows; the curves without bristles are always built exactly
        (a cusp at rest, shape 0.6, read at the rows' instants ranked below the smoother
        shapes where its filtered column was the best: 3 of about 60 scores on the
        proving ground's development seeds)."""
        return theta.get("stribeck_length", 0.0) > 0

    def coarse_batch(self, d, thetas, model):
        """The variants' columns read at the rows' instants (J, 1, m), without the rows'
        filter: the curve at each row's speed, the bristles' state run over the rows'
        positions (a tenth of the samples); what ranks the grid before its exact
        columns are built (:meth:`servo.physics.base.Search.coarse_batch`)."""
        if d.column_design(self.term, model) is not d:  # the arm's motion through a lag: every variant built exactly
            return None
        from kernels.stribeck import stribeck_bristle_trace

        sig = d.sig
        x, v = np.ascontiguousarray(sig.x_rows), np.ascontiguousarray(sig.v_rows)
        s = np.ascontiguousarray(sig.sign_v[sig.keep], dtype=float)
        C = np.empty((len(thetas), 1, v.size))
        for j, th in enumerate(thetas):
            vs, delta = th["stribeck_velocity"], th.get("stribeck_shape", GAUSSIAN)
            length = th.get("stribeck_length", 0.0)
            if length > 0:
                stribeck_bristle_trace(x, v, float(vs), float(delta), float(length), C[j, 0])
            else:
                C[j, 0] = s * curve(v, vs, delta)
        return C

    def held(self, theta):
        return ("stribeck_length",) if not theta.get("stribeck_length", 0.0) > 0 else ()  # no bristles stay none


class StribeckJudging(Judging):
    """A Stribeck rise must be one: ``dFs >= 0``."""

    def implausible(self, params: dict) -> str:
        if params["dFs"] < 0:
            return (f"the best fit has dFs = {params['dFs']:.3g} < 0: friction lower at low speed than sliding, a "
                    "smooth (pre-sliding-like) rise, the opposite of a Stribeck peak")  # fmt: skip
        return ""


class Stribeck(Term):
    name, coefs = "stribeck_friction", ("dFs",)
    thetas = ("stribeck_velocity", "stribeck_shape", "stribeck_length")
    units = {"dFs": "F", "stribeck_velocity": "m/s", "stribeck_shape": "-", "stribeck_length": "m",
             "Fs": "F"}  # Fs: a breakaway found at rest (breakaway.py)  # fmt: skip
    doc = ("Stribeck friction (Fs - Fc)*exp(-|x'/vs|^delta)*sgn(x'): higher friction at low speed; delta the "
           "curve's shape (2 the paper's Gaussian, 1 exponential); held by bristles of deflection "
           "stribeck_length at rest (LuGre), none at the length's lower bound")  # fmt: skip
    path = SignalPath(signs_by_input=True)  # without bristles its sign is the Coulomb column's
    search = StribeckSearch(requires=("coulomb_friction",))
    judging = StribeckJudging()

    def from_physical(self, p: dict) -> tuple[dict, tuple]:
        theta = {"stribeck_velocity": p["stribeck_velocity"], "stribeck_shape": p.get("stribeck_shape", GAUSSIAN),
                 "stribeck_length": p.get("stribeck_length", 0.0)}  # fmt: skip
        return theta, (p["dFs"],)

    def full(self, d, theta, u_eff):
        vs, delta = theta["stribeck_velocity"], theta.get("stribeck_shape", GAUSSIAN)
        length = theta.get("stribeck_length", 0.0)
        if not length > 0:  # no bristles: the curve's sign switches with the motion's
            return d.sig.sign_for(u_eff) * curve(d.sig.vf, vs, delta)
        return bristle_trace(d, vs, delta, length)

    def _range(self, d):
        v = valid_speed(d)
        return max(2.0 * d.sig.v_threshold, float(np.quantile(v, 0.02))), float(np.quantile(v, 0.75))

    def _lengths(self, d):
        """The bristle deflections on the grid (m): from what the sensor resolves
        (:func:`resolvable_length`, a millionth of the stroke) to ``LENGTH_MAX`` of the
        stroke (0: no bristles)."""
        span = float(np.ptp(d.sig.xf))
        return max(resolvable_length(d.sig), 1e-6 * span), LENGTH_MAX * span

    def grid(self, d, model):
        lo, hi = self._lengths(d)
        speeds = geom(*self._range(d), 5)
        plain = [{"stribeck_velocity": float(v), "stribeck_shape": s, "stribeck_length": 0.0} for s in SHAPES for v in speeds]
        held = [{"stribeck_velocity": float(v), "stribeck_shape": GAUSSIAN, "stribeck_length": float(L)}
                for L in geom(lo, hi, LENGTHS_PER_DECADE)[1:] for v in speeds[1::2]]  # fmt: skip
        return plain + held

    def bounds(self, d, model):
        return {"stribeck_velocity": (*self._range(d), True), "stribeck_shape": (*SHAPE_BOUNDS, True),
                "stribeck_length": (*self._lengths(d), True)}  # fmt: skip


class StribeckDrive(DriveMap):
    """The stribeck_friction term in the simulated drive's ``[drive]`` section."""

    name = "stribeck_friction"

    def to_drive(self, P, fit):
        p = P[self.name]  # the drive's curve is Gaussian: another shape as its Gaussian stand-in
        a, b = gaussian_stand_in(float(p.get("stribeck_shape", GAUSSIAN)))
        return {"Fs": P.get("coulomb_friction", {}).get("Fc", 0.0) + a * p["dFs"],
                "stribeck_velocity": b * p["stribeck_velocity"]}  # fmt: skip

    def state(self, design, theta, P, u, record):
        """The Dahl element that runs a bristle-held rise in the simulation (:func:`bristles`):
        its force at every sample, the rise's force beyond the lowered Coulomb level's."""
        b = bristles(P)
        if b is None:
            return None
        dFs, length = b
        vs, delta = theta["stribeck_velocity"], theta.get("stribeck_shape", GAUSSIAN)
        w = bristle_trace(design, vs, delta, length)
        return dFs * np.clip(w + design.sig.sign_v * (1.0 - curve(design.sig.vf, vs, delta)), -1.0, 1.0)

    def from_drive(self, d):
        if d.Fs > d.Fc and d.Fs > 0:
            return [({"stribeck_velocity": d.stribeck_velocity, "stribeck_shape": GAUSSIAN, "stribeck_length": 0.0},
                     (d.Fs - d.Fc,))]  # fmt: skip
        return []


#: the study's Coulomb level under the Stribeck rise it conceals, A
_SLIDING = 1e-3


def _conceal(size):
    return {"Fs": _SLIDING + size}


def _simulated(d, sim):
    b = bristles(sim.P)
    if b is not None and d["Fc"] > 0:  # the Coulomb level lowered by the rise, which a Dahl element holds
        rise = max(d["Fs"] - d["Fc"], 0.0)  # the Gaussian stand-in's (a*dFs)
        return {"Fs": max(d["Fc"] - b[0], 0.0) + rise, "stribeck_velocity": d.get("stribeck_velocity", 1.0)}
    return {"Fs": max(d["Fs"], 0.0) if d["Fc"] > 0 else 0.0, "stribeck_velocity": d.get("stribeck_velocity", 1.0)}


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
    simulated=_simulated,
    diagnosed_by="breakaway",
)  # fmt: skip

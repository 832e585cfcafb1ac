"""Dahl hysteresis (paper eq. 6-7): the pivot's pre-sliding friction with turnaround memory.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import numpy as np

from servo.fields import P
from servo.physics.base import SLIDING, Concealment, DriveMap, Effect, Judging, Search, Term, geom, number
from servo.physics.stribeck import bristles, resolvable_length


#: a fitted Dahl length at most this factor above the search's floor (the shortest
#: length the position noise resolves) is not resolved (:meth:`DahlJudging.implausible_on`)
UNRESOLVED = 2.0


class DahlJudging(Judging):
    """A Dahl element pushes against the motion (``Ha >= 0``) over a length the noise
    resolves; ``sigma``'s std from ``Ha``'s and the length's."""

    def std_extra(self, params, std):
        if "Ha" in std and "dahl_length" in std:
            rel = np.hypot(std["Ha"] / params["Ha"] if params["Ha"] else 0, std["dahl_length"] / params["dahl_length"])
            return {"sigma": float(params["sigma"] * rel)}
        return {}

    def implausible(self, params: dict) -> str:
        if params["Ha"] < 0:
            return f"the best fit has Ha = {params['Ha']:.3g} < 0: a force released after a reversal, not a Dahl friction"
        return ""

    def implausible_on(self, params: dict, d) -> str:
        """Also unphysical: a Dahl length within :data:`UNRESOLVED` of the shortest the
        search allows (:meth:`Hysteresis._range`: 10 std of the position noise, a millionth of the
        stroke).  The fit wants a rise shorter than the noise resolves, a force that
        switches at the reversal within the noise: not a Dahl element (low-pass-noise
        nulls got 2.4-2.8 nm with 1 nm of noise, the floor of the search)."""
        why = self.implausible(params)
        lo = self.term._range(d)[0]
        if not why and params["dahl_length"] <= UNRESOLVED * lo:
            why = (f"the best fit's Dahl length {params['dahl_length']:.3g} m is within {UNRESOLVED:g} x the shortest the "
                   f"position noise resolves ({lo:.3g} m): a switch at the reversal within the noise, not a Dahl element")
        return why


class Hysteresis(Term):
    name, coefs, thetas = "hysteresis", ("Ha",), ("dahl_length",)
    units = {"Ha": "F", "dahl_length": "m", "sigma": "F/m"}
    doc = ("Dahl hysteresis (paper eq. 6-7): a hidden force with turnaround memory, slope sigma at a "
           "reversal, asymptote +-Ha, Dahl length Ha/sigma")  # fmt: skip
    search = Search(requires=("coulomb_friction",))
    judging = DahlJudging()

    def full(self, d, theta, u_eff):
        s = d.sig
        out = np.empty(s.n)
        lam = theta["dahl_length"]
        from kernels.hysteresis import dahl_trace

        dahl_trace(s.xf, s.vf, s.v_threshold, 1.0 / lam, 1.0, float(theta.get("alpha", 1.0)), 0.0, out)
        return out

    def _range(self, d):
        s = d.sig
        span = float(np.ptp(s.xf))
        return max(resolvable_length(s), 1e-6 * span), 0.1 * span

    def grid(self, d, model):
        return [{"dahl_length": float(v)} for v in geom(*self._range(d), 3)]

    def bounds(self, d, model):
        return {"dahl_length": (*self._range(d), True)}

    def physical(self, theta, coef):
        p = super().physical(theta, coef)
        p["sigma"] = p["Ha"] / theta["dahl_length"]
        return p


class HysteresisDrive(DriveMap):
    """The hysteresis term in the simulated drive's ``[drive]`` section."""

    name = "hysteresis"
    #: no Dahl element: a negligible one (1e-12 A over a Dahl length of 1 m)
    absent = {"Ha": 1e-12, "sigma": 1e-12}

    def to_drive(self, P, fit):
        p = P[self.name]
        if not p["Ha"] > 0:
            return dict(self.absent)
        return {"Ha": p["Ha"], "sigma": p["sigma"], "alpha": fit.model.get(self.name).params.get("alpha", 1.0)}

    def from_drive(self, d):
        if d.Ha > 1e-6 * max(abs(d.h0), d.Fc, 1e-30):  # a written model without hysteresis has Ha = 1e-12
            return [({"dahl_length": d.Ha / d.sigma, "alpha": d.alpha}, (d.Ha,))]
        return []

    def state(self, design, theta, P, u, record):
        """The Dahl element's force H at every sample, from its turnaround memory."""
        if not P.get(self.name, {}).get("Ha", 0.0) > 0:
            return None
        return EFFECT.term.full(design, theta, u) * record["Ha"][0]


def _simulated(d, sim):
    if sim.P.get("hysteresis", {}).get("Ha", 0.0) > 0:
        return {"sigma": d["sigma"], "Ha": d["Ha"], "alpha": d.get("alpha", 1.0)}
    held = bristles(sim.P)
    if held is not None:  # a Stribeck rise held by bristles runs as a Dahl element (stribeck.bristles)
        return {"sigma": held[0] / held[1], "Ha": held[0], "alpha": 1.0}
    # no Dahl element: a negligible one that never saturates (Dahl length 1 m), since
    # the plant's closed form overflows for a saturated element of vanishing length
    off = 1e-12 * sim.u_scale
    return {"sigma": off, "Ha": off, "alpha": 1.0}


def _conceal(size):
    return {"Ha": size, "sigma": size / 3e-6}


def _leave_out(d):
    d.update(HysteresisDrive.absent)


_STUDY = Concealment("hysteresis", "A", "Dahl Ha (Dahl length 3 um)", (1e-5, 2e-5, 5e-5, 1e-4, 2e-4), 1e-3,
                     fields=_conceal)


#: a Dahl element below this fraction of the model's largest force is no Dahl element
NEGLIGIBLE = 1e-6
#: Dahl lengths after a turnaround before eq. (3)'s regime may take over: the Dahl
#: estimate is then within exp(-4) = 2 % of its asymptote (the default config's 12.5 um
#: over its 3.125 um Dahl length)
SATURATED = 4.0


def _cancel(d, how):
    """The Dahl element (eq. 6-7) with eq. (3)'s sliding level; with ``how.paper`` one
    sliding level for both, the drive's Coulomb level beyond the Dahl element added."""
    Ha, sigma, alpha = number(d, "Ha", 1e-12), number(d, "sigma", 1e-12), number(d, "alpha", 1.0)
    Fc, Fs = number(d, "Fc"), number(d, "Fs")
    scale = max(abs(Ha), abs(Fc), abs(Fs), abs(number(d, "h0")), 1e-300)
    dahl = Ha > NEGLIGIBLE * scale
    if how.paper:
        level = (Ha if dahl else 0.0) + Fc  # one sliding level, as eq. (9) has
        length = Ha / sigma if dahl else how.dahl_length
        if level > 0:
            keys = dict(sliding_level=level, Ha=level, sigma=level / length, alpha=alpha if dahl else 1.0,
                        fast_on_distance=SATURATED * length)  # fmt: skip
        else:
            keys = dict(sliding_level=0.0, Ha=1e-12, sigma=1e-12, alpha=1.0)
        return [("sliding friction (eq. 9: Coulomb and its Dahl element)", keys)]
    keys = dict(sigma=sigma, Ha=Ha, alpha=alpha, sliding_level=Ha)
    if dahl:
        keys["fast_on_distance"] = SATURATED * Ha / sigma
    return [("Dahl hysteresis (eq. 6-7)" if dahl else "Dahl hysteresis: none in the model (the term off)", keys)]


EFFECT = Effect(
    "hysteresis", "Dahl hysteresis (eq. 6-7): pre-sliding friction with turnaround memory",
    drive=dict(
        sigma=P(320.0, "A/m", "Dahl pre-sliding stiffness (slope at a turnaround)", 0.0, None, lo_open=True),
        Ha=P(1.0e-3, "A", "Dahl asymptote = pivot sliding friction level", 0.0, None, lo_open=True),
        alpha=P(1.0, "-", "Dahl shape exponent", 0.0, 10.0, lo_open=True),
    ),
    compensator=dict(
        sliding_level=P(1.0e-3, "A", "sliding friction level of eq. 3, the large-motion regime's Fc*sgn(v) (the Dahl "
                        "asymptote Ha when that is the whole sliding friction)", None, None),
        sigma=P(320.0, "A/m", "Dahl slope estimate (eq. 6)", 0.0, None, lo_open=True),
        Ha=P(1.0e-3, "A", "Dahl asymptote estimate (eq. 6)", 0.0, None, lo_open=True),
        alpha=P(1.0, "-", "Dahl exponent estimate (eq. 6)", 0.0, 10.0, lo_open=True),
    ),
    plant=lambda d, dt: {"sigma": d.sigma, "Ha": d.Ha, "alpha": d.alpha},
    stage=lambda c: {"Fc": c.sliding_level, "sigma": c.sigma, "Ha": c.Ha, "alpha": c.alpha},
    term=Hysteresis(),
    renamed={"compensator.Fc": "sliding_level"},
    drive_map=HysteresisDrive(),
    leave_out=_leave_out,
    study=_STUDY,
    simulated=_simulated,
    cancel=_cancel,
    forces=lambda f, stroke, speed: {SLIDING: max(abs(number(f, "sliding_level")), abs(number(f, "Ha")))},
)  # fmt: skip

"""Only what was found becomes compensation: a term whose fitted size is not
distinguishable from zero is left out of the compensator.

A diagnosis (or an identification) reports each term's coefficients with their standard
deviations (``report.json``: ``final_model.terms[*].std``, from the fit's covariance with
the residual's correlation time; ``servo.diagnose.fit.fit_model``).  A term is
*significant* when at least one of its coefficients lies more than ``z`` standard
deviations from zero, ``z`` the two-sided normal quantile of the diagnosis's own level
(``settings.alpha``, 5 % by default: ``z = 1.96``).  A term that is not is left out: its
drive fields are set to what the drive holds without it (:data:`LEAVE_OUT`), so the
mirror (:mod:`servo.compensate.propose`) writes no compensator term for it; eq. (9)'s
sliding level then folds only what was found.

A baseline term's noise is the case in point: a Dahl pivot with no Coulomb friction
beyond its Dahl element, diagnosed with the baseline ``J,B,Fc,K,h0``, gets a small
Coulomb level of either sign (tens of uA against the pivot's mA, within two standard
deviations of zero); cancelling it would push the arm by a force it does not have.

Not tested: a term with no standard deviation (a model file's fixed term, a config's
exact values), the inertia (not a compensator term) and the terms no static term
cancels (:data:`servo.compensate.model.NOT_CANCELLABLE`).
"""
from __future__ import annotations

import dataclasses

from scipy import stats

from servo.compensate.model import SourceModel
from servo.physics import EFFECTS, VOCABULARY


#: physics -> how a drive's fields read without the term (in place): each compensator
#: term's own :attr:`~servo.physics.base.Effect.leave_out`
LEAVE_OUT = {name: EFFECTS[name].leave_out for name in VOCABULARY if EFFECTS[name].leave_out is not None}


def z_level(alpha: float) -> float:
    """The two-sided normal quantile of the level ``alpha``."""
    return float(stats.norm.isf(alpha / 2.0))


@dataclasses.dataclass
class LeftOut:
    """A term left out: ``physics``, its ``params``, ``std`` and ``units`` (the model's
    force unit) and the largest ``|value|/std`` of its coefficients against ``z``."""

    physics: str
    params: dict
    std: dict
    units: dict
    t: float
    z: float

    def describe(self) -> str:
        sizes = ", ".join(f"{k} {v:.3g} +- {self.std[k]:.2g}{' ' + self.units[k] if k in self.units else ''}"
                          for k, v in self.params.items() if k in self.std)  # fmt: skip
        return (f"{self.physics} ({sizes}; {self.t:.2f} standard deviations from zero, under the {self.z:.2f} of the "
                "diagnosis's level): not distinguishable from zero")  # fmt: skip


def significant(model: SourceModel) -> tuple[SourceModel, list[LeftOut]]:
    """``model`` without its insignificant terms (module doc), and what was left out.
    A term appearing twice (a model file's fixed term and its fitted correction) is
    tested on its fitted part only; a term counts as found if any part of it is."""
    z = z_level(model.alpha)
    found: dict[str, bool] = {}
    tested: dict[str, LeftOut] = {}
    for s in model.sizes:
        if s.physics not in LEAVE_OUT:
            continue
        ts = [abs(s.params[k]) / s.std[k] for k in s.params if s.std.get(k, 0.0) > 0]
        if not ts:  # fixed or without a standard deviation: kept as given
            found[s.physics] = True
            continue
        t = max(ts)
        found[s.physics] = found.get(s.physics, False) or t > z
        if t <= z:
            tested[s.physics] = LeftOut(s.physics, dict(s.params), dict(s.std), dict(s.units), t, z)
    out = [tested[name] for name in tested if not found[name]]
    if not out:
        return model, []
    drive = dict(model.drive)
    for lo in out:
        LEAVE_OUT[lo.physics](drive)
    physics = [p for p in model.physics if p not in {lo.physics for lo in out}]
    return dataclasses.replace(model, drive=drive, physics=physics), out


__all__ = ["LEAVE_OUT", "LeftOut", "significant", "z_level"]

"""A model the compensator may be written from: its terms within the plant's physical
range and the current limit.

The authority (:mod:`servo.compensate.propose`) keeps a wrong model from destabilising
the loop, but not from spending the whole authority on a force the drive never had: a
bias of 1e11 A is clipped to the authority, and the loop then tracks to a millimetre.  A
model is refused, with the reason, when a term

* needs more than the current limit ``u_max`` (the base config's ``[controller]
  current_limit``, the command's unit) anywhere the arm can be: each force the effects
  declare (their :attr:`~servo.physics.base.Effect.forces`, the entries of one name
  added, :func:`servo.physics.largest_forces`) over the stroke and up to the largest
  speed the recording reached (when the source says it): the bias at the stroke
  (``|h0| + |K|*stroke + |k3|*stroke^3``), the sliding level (the Dahl asymptote plus
  the Coulomb element's largest level, times ``1 + |asymmetry|``), a periodic force's
  amplitude, an input dead zone's half-width, the viscous force at that speed;
* puts a rate of the rigid body beyond the Nyquist frequency of the loop that would run
  the compensator (the base config's rate): each effect's
  :attr:`~servo.physics.base.Effect.rates` (the viscous pole ``|B|/J``, the spring's
  natural frequency ``sqrt(|K|/J)``), in rad/s, above ``pi*rate``; the sampled loop
  cannot see such a plant, let alone cancel it.
"""
from __future__ import annotations

import math

from servo import physics
from servo.config import Config


def implausible(d: dict, base: Config, unit: str = "A", speed: float | None = None) -> list[str]:
    """The reasons (one phrase each; empty: plausible) the drive fields ``d`` (in the
    command's unit ``unit``, m, s) cannot be a model of a drive run by ``base`` (module
    doc); ``speed`` (m/s): the largest speed of the recording, None if unknown."""
    u_max = base.controller.current_limit
    stroke = base.drive.stroke
    J = float(d.get("J", base.drive.J))
    nyquist = math.pi / base.dt  # rad/s
    out = []
    for what, size in physics.largest_forces(d, stroke, speed).items():  # every effect's forces hook
        if size > u_max:
            out.append(f"the {what} {size:.3g} {unit} is beyond the current limit {u_max:.3g} {unit}")
    for what, rate in physics.rates(d, J).items():  # every effect's rates hook
        if rate > nyquist:
            out.append(f"the {what} = {rate:.3g} rad/s ({rate / (2 * math.pi):.3g} Hz) is beyond the loop's "
                       f"Nyquist frequency {nyquist:.3g} rad/s ({0.5 / base.dt:.6g} Hz)")  # fmt: skip
    return out


__all__ = ["implausible"]

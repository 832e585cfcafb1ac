"""A model the compensator may be written from: its terms within the plant's physical
range and the current limit.

The authority (:mod:`servo.compensate.propose`) keeps a wrong model from destabilising
the loop, but not from spending the whole authority on a force the drive never had: a
bias of 1e11 A is clipped to the authority, and the loop then tracks to a millimetre.  A
model is refused, with the reason, when a term

* needs more than the current limit ``u_max`` (the base config's ``[controller]
  current_limit``, the command's unit) anywhere the arm can be: the bias
  ``|h0| + |K|*stroke + |k3|*stroke^3``, an input dead zone's half-width, the sliding level ``max(Ha, Fc, Fs)*(1 + |asymmetry|)``, a
  periodic force's amplitude, or the viscous force ``|B|*(1 + |b_asymmetry|)*v`` at the
  largest speed the recording reached (when the source says it);
* puts a pole of the rigid body beyond the Nyquist frequency of the loop that would run
  the compensator (the base config's rate): the viscous pole ``|B|/J`` or the spring's
  natural frequency ``sqrt(|K|/J)``, in rad/s, above ``pi*rate``; the sampled loop
  cannot see such a plant, let alone cancel it.
"""
from __future__ import annotations

import math

from servo.config import Config


def implausible(d: dict, base: Config, unit: str = "A", speed: float | None = None) -> list[str]:
    """The reasons (one phrase each; empty: plausible) the drive fields ``d`` (in the
    command's unit ``unit``, m, s) cannot be a model of a drive run by ``base`` (module
    doc); ``speed`` (m/s): the largest speed of the recording, None if unknown."""
    g = lambda k, default=0.0: abs(float(d.get(k, default)))  # noqa: E731
    u_max = base.controller.current_limit
    stroke = base.drive.stroke
    J = float(d.get("J", base.drive.J))
    nyquist = math.pi / base.dt  # rad/s
    out = []
    bias = g("h0") + g("K") * stroke + g("k3") * stroke**3
    if bias > u_max:
        cubic = f" + |k3|*stroke^3 ({g('k3'):.3g} {unit}/m^3)" if g("k3") else ""
        out.append(f"the bias |h0| + |K|*stroke{cubic} = {g('h0'):.3g} + {g('K'):.3g}*{stroke:.3g} m"
                   f"{' + ...' if cubic else ''} = {bias:.3g} {unit} is beyond the current limit {u_max:.3g} {unit}")  # fmt: skip
    if g("dead_zone") > u_max:
        out.append(f"the input dead zone's half-width {g('dead_zone'):.3g} {unit} is beyond the current limit "
                   f"{u_max:.3g} {unit}")  # fmt: skip
    sliding = max(g("Ha", 1e-12), g("Fc"), g("Fs")) * (1 + g("fc_asymmetry"))
    if sliding > u_max:
        out.append(f"the sliding friction level {sliding:.3g} {unit} is beyond the current limit {u_max:.3g} {unit}")
    if g("cogging") > u_max:
        out.append(f"the periodic force's amplitude {g('cogging'):.3g} {unit} is beyond the current limit "
                   f"{u_max:.3g} {unit}")  # fmt: skip
    if speed is not None and g("B") * (1 + g("b_asymmetry")) * speed > u_max:
        out.append(f"the viscous force |B|*v = {g('B'):.3g} {unit}*s/m * {speed:.3g} m/s at the recording's largest "
                   f"speed is beyond the current limit {u_max:.3g} {unit}")  # fmt: skip
    if g("B") / J > nyquist:
        out.append(f"the viscous pole |B|/J = {g('B') / J:.3g} rad/s is beyond the loop's Nyquist frequency "
                   f"{nyquist:.3g} rad/s ({0.5 / base.dt:.6g} Hz)")  # fmt: skip
    if math.sqrt(g("K") / J) > nyquist:
        out.append(f"the natural frequency sqrt(|K|/J) = {math.sqrt(g('K') / J) / (2 * math.pi):.3g} Hz is beyond the "
                   f"loop's Nyquist frequency {0.5 / base.dt:.6g} Hz")  # fmt: skip
    return out


__all__ = ["implausible"]

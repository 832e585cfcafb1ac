"""A compensator for a model: each cancellable term of the drive's physics mirrored by its
compensator term, with an authority that bounds what a wrong model can do.

**The mirror.**  The compensator cancels the drive's forces one for one (``kernels/stage.py``,
``kernels/cancel.py``), so with exact estimates the plant the controller sees is
``J*x'' = u_n`` (eq. 10).  Which ``[drive]`` fields each compensator term mirrors is the
effect's own ``cancel`` hook (:mod:`servo.physics`; the table of both sections' fields
per effect is ``docs/model.md``'s, :func:`servo.physics.markdown_table`).

``paper=True`` writes what eq. (9) alone can hold of the model: one sliding-friction
level ``sliding_level = Ha + Fc`` (the drive's Coulomb level beyond the Dahl element
added) for both the Dahl asymptote and the large-motion regime, and none of the terms
beyond it (the paper's compensator identified on this drive).

**The authority** (docs/compensate.md).  A compensator term is a feedback of the measured
motion; a wrong one (a sign, an over-fit, a term extrapolated beyond the motion it was
fitted on) must not destabilise the loop:

* ``authority`` bounds ``|u_c|``: whatever the model, the loop then sees its designed
  linear loop plus a bounded input, so nothing diverges; a wrong force of amplitude ``A``
  at one frequency moves the head by at most ``A*max|P*S|`` (reported).  It is the
  model's own largest force over the motion it was found on (its speeds and positions),
  times :data:`MARGIN`, and never more than :data:`U_FRACTION` of the current limit
  (that fraction alone when the source does not say how fast the arm moved).
* ``kf_authority`` bounds the divisor ``kf(x)`` within ``1 +- a``: a multiplicative change
  of the loop gain by at most ``1/(1-a)``.  ``a`` is the model's own largest ``|kf-1|``
  over the stroke times :data:`MARGIN`, and never more than what half the designed loop's
  gain margins allow (:func:`kf_bound`): the gain may rise by ``1/(1-a)`` and fall by
  ``1/(1+a)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from servo.compensate.model import NOT_CANCELLABLE, CompensateError, SourceModel
from servo.compensate.plausible import implausible
from servo.compensate.significance import significant
from servo import physics
from servo.config import Config, from_dict, to_dict
from servo.physics.base import Cancelling

#: The authority is this times the largest force (or kf change) the model itself makes.
MARGIN = 1.5
#: and never more than this fraction of the current limit.
U_FRACTION = 0.5


@dataclass
class Term:
    """One line of a proposal: ``name`` what it cancels, ``keys`` the compensator fields
    it sets; ``advice`` (for what cannot be cancelled) what to do instead."""

    name: str
    keys: dict = field(default_factory=dict)
    advice: str = ""


@dataclass
class Proposal:
    """``section``: the ``[compensator]`` fields (A, m, s; valid for
    :class:`servo.config.CompensatorConfig`); ``cancelled``/``not_cancelled``: per term;
    ``authority``: how it is bounded (``authority_a``, ``largest_force_a``,
    ``kf_authority``, ``kf_model``, ``gain_up_db``/``gain_down_db`` (the loop's gain margins), ``worst_um_per_ma``: the head's
    largest response (um) to 1 mA of wrong force at any frequency, None if not computed;
    the ``_a`` figures are in ``unit``); ``unit``: the force unit of the section (the
    command's: "A", or the model's own when it was not converted); ``left_out``: the terms
    not distinguishable from zero (:class:`~servo.compensate.significance.LeftOut`)."""

    source: str
    paper: bool
    section: dict
    cancelled: list
    not_cancelled: list
    authority: dict
    unit: str = "A"
    left_out: list = field(default_factory=list)
    #: the model's position unit: m, or rad for a rotary axis (the section's m reads rad)
    position_unit: str = "m"


def mirror(d: dict, paper: bool = False, dahl_length: float = 3.125e-6, c=None) -> list[Term]:
    """The compensator terms of the drive fields ``d`` (see module doc): each effect's own
    (its ``cancel`` hook, :func:`servo.physics.cancel_terms`, in the order the stage
    applies them to the compensator section ``c``, default the default one);
    ``dahl_length`` (m) is the Dahl element's when ``paper`` folds a Coulomb level
    without one."""
    c = Config().compensator if c is None else c
    return [Term(name, keys) for name, keys in physics.cancel_terms(d, Cancelling(paper, dahl_length), c)]


def largest_force(c: dict, speed: float, position: float) -> float:
    """The largest ``|u_c|`` (A) the compensator fields ``c`` make at speeds up to
    ``speed`` (m/s) and positions up to ``|position|`` (m), bounding each term by its
    largest magnitude (a sum: the terms may line up): every effect's
    :attr:`~servo.physics.base.Effect.forces` (:func:`servo.physics.largest_forces`)."""
    return sum(physics.largest_forces(c, abs(position), speed).values())


def kf_change(c: dict) -> float:
    """The largest ``|kf(x) - 1|`` of the force-constant fields over ``|x| <= kf_stroke``."""
    k1, k2 = c.get("kf_linear", 0.0), c.get("kf_quadratic", 0.0)
    r = np.linspace(-1.0, 1.0, 2001)
    return float(np.max(np.abs(k1 * r + k2 * r * r)))


def loop_margins(cfg: Config) -> tuple[float | None, float | None, float | None]:
    """``(gain up dB, gain down dB, max|P*S| m/A)`` of the designed loop of ``cfg`` (its
    controller on the compensated drive, eq. 10, with the drive's modes and delay): how
    much the loop gain may rise (the smallest positive gain margin) and fall (the
    smallest negative one, a conditionally stable loop: a double integrator under a lead
    has one) before the loop is unstable; None where there is none or they cannot be
    computed."""
    from servo.loop.design import design_grid, loop_design
    from servo.design.margins import margins

    f = design_grid(cfg, 1.0, 0.45 / cfg.dt, 1500)
    try:
        design = loop_design(cfg, f, model="drive")  # its modes and delay: where the margins are
        gms = [g for g in margins(f, design.L, dense=True)["gain_margins"] if math.isfinite(g["db"])]
        ps = np.abs(design.P * design.S)
        worst = float(np.max(ps[np.isfinite(ps)]))
    except (ValueError, NotImplementedError):
        return None, None, None
    up = min((g["db"] for g in gms if g["side"] == "upper"), default=None)
    down = max((g["db"] for g in gms if g["side"] == "lower"), default=None)
    return up, down, worst


def kf_bound(up: float | None, down: float | None) -> float:
    """The largest ``a`` such that dividing by ``kf`` in ``1 +- a`` moves the loop gain by
    at most half of each gain margin: ``20*log10(1/(1-a)) <= up/2`` and
    ``20*log10(1+a) <= |down|/2`` (0.9 when the loop has neither)."""
    a = 0.9
    if up is not None:
        a = min(a, 1.0 - 10.0 ** (-up / 40.0))
    if down is not None:
        a = min(a, 10.0 ** (-down / 40.0) - 1.0)
    return a


def propose(model: SourceModel, base: Config, paper: bool = False, force_constant: float | None = None,
            authority: float | None = None, significant_only: bool = True) -> Proposal:  # fmt: skip
    """The compensator section for ``model`` on the config ``base`` (its controller, its
    current limit, its drive's stroke).  ``force_constant`` (N/A) converts a model in N
    to A; without it the section is in the model's own unit (:attr:`Proposal.unit`: the
    loop that runs it commands that unit).  ``authority`` (the section's unit) overrides
    the computed bound on ``|u_c|``.  ``significant_only``: leave out the terms not
    distinguishable from zero (:mod:`servo.compensate.significance`).  Raises
    :class:`~servo.compensate.model.CompensateError` for a model beyond the plant's
    physical range (:mod:`servo.compensate.plausible`)."""
    left_out = []
    if significant_only:
        model, left_out = significant(model)
    d = dict(model.drive)
    unit = model.force_unit
    if model.force_unit != "A" and force_constant is not None:
        if not force_constant > 0 or not math.isfinite(force_constant):
            raise ValueError(f"--force-constant {force_constant!r}: expected a positive number of {unit}/A")
        for k in physics.force_fields():  # the fields whose declared unit is in the force unit
            if k in d:
                d[k] = float(d[k]) / force_constant
        unit = "A"
    bad = implausible(d, base, unit, model.speed_max)
    if bad:
        raise CompensateError(f"{model.source}: not a model of a drive this config can run: {'; '.join(bad)}")
    terms = mirror(d, paper, base.compensator.Ha / base.compensator.sigma, base.compensator)
    section: dict = {}
    for t in terms:
        section.update(t.keys)
    not_cancelled = [Term(name, advice=NOT_CANCELLABLE[name]) for name in dict.fromkeys(model.physics)
                     if name in NOT_CANCELLABLE]  # fmt: skip
    speed = model.speed_max if model.speed_max else None
    position = model.position_max if model.position_max else base.drive.stroke
    largest = largest_force(section, speed, position) if speed is not None else None
    u_lim = base.controller.current_limit
    auth = U_FRACTION * u_lim if largest is None else min(U_FRACTION * u_lim, MARGIN * largest)
    auth = authority if authority is not None else auth
    section["authority"] = float(auth)
    # the designed loop is the base config's: the recorded axis's only for a model in A and m
    loop_is_source = model.force_unit == "A" and model.position_unit == "m"
    info: dict = dict(authority_a=float(auth), largest_force_a=largest, speed_m_s=speed, position_m=position,
                      current_limit_a=u_lim, kf_model=None, kf_authority=None, gain_up_db=None, gain_down_db=None,
                      worst_um_per_ma=None, loop_is_source=loop_is_source)  # fmt: skip
    up = down = None
    if loop_is_source:
        up, down, worst = loop_margins(base.replace(compensator={k: v for k, v in section.items()}))
        info.update(gain_up_db=up, gain_down_db=down)
        info["worst_um_per_ma"] = worst * 1e6 * 1e-3 if worst is not None else None
    if "kf_linear" in section:
        a_model = kf_change(section)
        a = float(max(min(MARGIN * a_model, kf_bound(up, down)), 1e-3))
        section["kf_authority"] = a
        info.update(kf_model=a_model, kf_authority=a)
    from_dict({"compensator": section})  # every value within its declared range, or ConfigError
    return Proposal(model.source, paper, section, terms, not_cancelled, info, unit, left_out, model.position_unit)


def apply(base: Config, p: Proposal) -> Config:
    """``base`` with its ``[compensator]`` replaced by the proposal's (on the defaults of
    the fields it does not set: a term the model lacks is off)."""
    data = to_dict(base)
    data["compensator"] = {"enabled": True, **p.section}
    return from_dict(data)


__all__ = ["MARGIN", "U_FRACTION", "Proposal", "Term", "apply", "largest_force", "kf_bound", "loop_margins", "mirror", "propose"]

"""The physical effects of the drive, one module each, and the registry that gathers them.

Each module (``servo/physics/<effect>.py``) declares one :class:`~servo.physics.base.Effect`:
its ``[drive]`` and ``[compensator]`` config fields, its part of the plant record and of
the compensator stage's record, its diagnosis term, why it cannot be cancelled (if it
cannot) and its documentation line.  The registry derives from them:

* the fields of the config sections (:func:`drive_fields`, :func:`compensator_fields`,
  gathered by :mod:`servo.config`);
* the one config-to-record mapping of the simulated drive (:func:`plant_values`, used by
  :func:`servo.runtime.simplant.plant_params` for the runtime, the diagnosis and the
  studies alike) and of the compensator (:func:`stage_values`);
* the vocabulary of the diagnosis (:data:`VOCABULARY`, :data:`NAMES`);
* the holding current at start (:func:`rest_force`, :func:`force_gain`,
  :func:`command_for`), the forces a model's current must cover (:func:`largest_forces`)
  and the fields a force constant converts (:func:`force_fields`);
* the docs tables (:func:`markdown_table`).

Adding an effect is one module here and one entry in :data:`MODULES`.
"""
from __future__ import annotations

import dataclasses
from importlib import import_module

import numpy as np

from servo.physics.base import Cancelling, Concealment, Effect, Term

#: the effect modules, in the order the config sections list their fields and the
#: diagnosis's vocabulary lists its terms
MODULES = (
    "inertia", "viscous", "coulomb", "stiffness", "offset", "asymmetric", "stribeck", "hysteresis", "resonance",
    "time_delay", "saturation", "position_gain", "cogging", "quantization", "sensor_lag", "stops", "noise",
    "dead_zone",
    "cubic_spring",
    "backlash",
    "drift",
)  # fmt: skip

#: effect name -> its :class:`~servo.physics.base.Effect`
EFFECTS: dict[str, Effect] = {}

#: effect name -> the file that declares it
FILES: dict[str, str] = {}

#: vocabulary name -> the diagnosis term (every effect with one; terms that live with
#: the diagnosis's signal path register themselves, :func:`register_term`)
VOCABULARY: dict[str, Term] = {}

#: every physics name a finding can carry (each effect whose diagnosis term has a
#: ``drive_map``, in registry order): derived from the modules below
NAMES: tuple[str, ...] = ()

#: the baseline terms of eq. (3) and the vocabulary term each is
BASELINE_TERMS = {"J": "inertia", "B": "viscous_friction", "Fc": "coulomb_friction", "K": "stiffness", "h0": "offset"}

#: the term whose coefficient ``J`` is the moving mass (the force balance's scale: a
#: model without a positive one cannot be simulated, its size says whether the
#: recording is in scope)
MASS = BASELINE_TERMS["J"]


def register(effect: Effect) -> None:
    """Add ``effect`` to :data:`EFFECTS` (and its term to :data:`VOCABULARY`), refusing a
    name or a config field another effect already has."""
    if effect.name in EFFECTS:
        raise ValueError(f"physics: an effect named {effect.name!r} is already registered")
    for section in ("drive", "compensator"):
        mine = getattr(effect, section)
        for other in EFFECTS.values():
            both = set(mine) & set(getattr(other, section))
            if both:
                raise ValueError(f"physics: {effect.name} declares [{section}] {', '.join(sorted(both))}, "
                                 f"already {other.name}'s")  # fmt: skip
    EFFECTS[effect.name] = effect
    if effect.term is not None:
        if effect.term.name != effect.name:
            raise ValueError(f"physics: effect {effect.name!r} carries the term {effect.term.name!r}")
        VOCABULARY[effect.name] = effect.term


def register_term(cls) -> None:
    """Add a diagnosis term defined beside the diagnosis (its columns need the
    diagnosis's signal path) to :data:`VOCABULARY`; its effect is a module here."""
    if cls.name not in EFFECTS:
        raise ValueError(f"physics: the term {cls.name!r} has no effect module in servo.physics")
    VOCABULARY[cls.name] = cls()


def drive_fields() -> list[tuple[str, dataclasses.Field]]:
    """``(name, field)`` of every effect's ``[drive]`` fields, in registry order."""
    return [item for e in EFFECTS.values() for item in e.drive.items()]


def compensator_fields() -> list[tuple[str, dataclasses.Field]]:
    """``(name, field)`` of every effect's ``[compensator]`` fields, in registry order."""
    return [item for e in EFFECTS.values() for item in e.compensator.items()]


def renamed_keys() -> dict[str, str]:
    """Former config keys, ``"section.old" -> "new"``, of every effect."""
    return {old: new for e in EFFECTS.values() for old, new in e.renamed.items()}


def owner(section: str, key: str) -> Effect | None:
    """The effect that declares the config field ``[section] key`` (None: the section's own)."""
    for e in EFFECTS.values():
        if key in getattr(e, section):
            return e
    return None


def plant_values(d, dt: float) -> dict:
    """The :data:`~kernels.plant.PLANT_PARAMS` fields every effect sets from the drive
    section ``d`` at sample period ``dt`` (s)."""
    out = {}
    for e in EFFECTS.values():
        if e.plant is not None:
            out.update(e.plant(d, dt))
    return out


def stage_values(c) -> dict:
    """The :data:`~kernels.stage.STAGE_PARAMS` fields every effect's compensator term
    sets from the compensator section ``c``, and ``extras``: 1 when any term beyond the
    paper's eq. (9) is engaged."""
    out = {}
    for e in EFFECTS.values():
        if e.stage is not None:
            out.update(e.stage(c))
    out["extras"] = 1.0 if any(e.engaged(c) for e in EFFECTS.values() if e.engaged is not None) else 0.0
    return out


def simulated_drive(d: dict, sim) -> dict:
    """The ``[drive]`` fields of the short-horizon simulation of a fitted model whose
    fields are ``d``: each effect's (:meth:`~servo.physics.base.Effect.simulation`,
    :class:`~servo.physics.base.Simulation`)."""
    out = {}
    for e in EFFECTS.values():
        mine = e.simulation(d, sim)
        if not set(mine) <= set(e.drive):
            raise ValueError(f"physics: {e.name} simulates fields it does not declare: "
                             f"{sorted(set(mine) - set(e.drive))}")
        out.update(mine)
    return out


def cancel_terms(d: dict, how, c) -> list[tuple[str, dict]]:
    """The compensator terms of a model whose ``[drive]`` fields are ``d`` (a dict), each
    ``(what it cancels, its [compensator] fields)``: every effect's ``cancel`` hook
    (:class:`~servo.physics.base.Cancelling` ``how``), the entries of one name one term,
    in the order the compensator stage applies them (the first of their effects'
    :data:`~kernels.stage.STAGE_PARAMS` fields, as ``stage(c)`` sets them from the
    compensator section ``c``)."""
    from kernels.stage import STAGE_PARAMS

    names = STAGE_PARAMS.names
    terms: dict[str, dict] = {}
    rank: dict[str, int] = {}
    for e in EFFECTS.values():
        for name, keys in (e.cancel(d, how) if e.cancel is not None else []):
            terms.setdefault(name, {}).update(keys)
            r = min(names.index(k) for k in e.stage(c)) if e.stage is not None else len(names)
            rank[name] = min(rank.get(name, r), r)
    return sorted(terms.items(), key=lambda item: rank[item[0]])


def rest_force(d, x: float) -> float:
    """The force (the drive's force unit) every effect of the drive section ``d`` exerts
    on the arm at rest at position ``x`` (m), the Dahl element relaxed (``H = 0``): the
    sum of their ``rest_force`` hooks, in registry order."""
    f = None
    for e in EFFECTS.values():
        v = e.rest_force(d, x) if e.rest_force is not None else 0.0
        if v != 0.0:  # a force that is not there adds nothing, not even a zero's sign
            f = v if f is None else f + v
    return 0.0 if f is None else f


def force_gain(d, x: float) -> float:
    """The force constant's factor at position ``x`` (m) of the drive section ``d``: the
    product of the effects' ``force_gain`` hooks (1 with none)."""
    g = 1.0
    for e in EFFECTS.values():
        if e.force_gain is not None:
            g *= e.force_gain(d, x)
    return g


def command_for(d, u: float) -> float:
    """The command whose force on the arm is ``u`` through the input elements of the
    drive section ``d`` (each effect's ``command_for`` hook, in registry order)."""
    for e in EFFECTS.values():
        if e.command_for is not None:
            u = e.command_for(d, u)
    return u


def largest_forces(f: dict, stroke: float, speed: float | None) -> dict[str, float]:
    """What -> the largest ``|force|`` (force unit) the fields ``f`` (a dict of
    ``[drive]`` or ``[compensator]`` fields) make at positions up to ``stroke`` (m) and
    speeds up to ``speed`` (m/s; None: unknown): every effect's ``forces`` hook, the
    entries of one ``what`` added (the terms may line up), in registry order."""
    out: dict[str, float] = {}
    for e in EFFECTS.values():
        if e.forces is not None:
            for what, size in e.forces(f, stroke, speed).items():
                out[what] = out.get(what, 0.0) + size
    return out


def rates(f: dict, J: float) -> dict[str, float]:
    """What -> the rigid body's rate (rad/s) the fields ``f`` make with the moving mass
    ``J``: every effect's ``rates`` hook, in registry order."""
    out: dict[str, float] = {}
    for e in EFFECTS.values():
        if e.rates is not None:
            out.update(e.rates(f, J))
    return out


def force_fields() -> tuple[str, ...]:
    """Every config field in the force unit (its declared unit ``A``, ``A/m``, ``A*s/m``,
    ...: the fields a force constant converts), either section's, in registry order."""
    out = []
    for e in EFFECTS.values():
        for k, fld in {**e.drive, **e.compensator}.items():
            unit = fld.metadata.get("unit", "")
            if (unit == "A" or unit.startswith(("A/", "A*"))) and k not in out:
                out.append(k)
    return tuple(out)


def fill(record: np.ndarray, values: dict) -> None:
    """Write ``values`` into the one-element ``record``: a scalar field whole, an array
    field's first ``len(value)`` entries."""
    for k, v in values.items():
        if record.dtype[k].shape:
            v = np.asarray(v, dtype=float)
            record[k][0, : v.size] = v
        else:
            record[k] = v


def diagnosed_by(stage: str) -> str:
    """The name of the effect whose term the diagnosis stage ``stage`` names
    (:attr:`~servo.physics.base.Effect.diagnosed_by`)."""
    names = [e.name for e in EFFECTS.values() if e.diagnosed_by == stage]
    if len(names) != 1:
        raise ValueError(f"physics: the diagnosis stage {stage!r} names {len(names)} effects, not one")
    return names[0]


def not_cancellable() -> dict[str, str]:
    """Vocabulary name -> why no static compensator term cancels it (the terms a
    diagnosis can name that the compensator leaves alone)."""
    return {e.name: e.not_cancellable for e in EFFECTS.values() if e.not_cancellable and e.name in NAMES
            and e.name not in BASELINE_TERMS.values()}  # fmt: skip


def markdown_table() -> str:
    """The effects as a Markdown table: name, what it is, its config fields, whether the
    compensator cancels it (``docs/model.md``)."""
    out = ["| effect | file | what | `[drive]` fields | `[compensator]` fields |", "|---|---|---|---|---|"]
    for e in EFFECTS.values():
        drive = ", ".join(f"`{k}`" for k in e.drive) or "-"
        comp = ", ".join(f"`{k}`" for k in e.compensator) or ("not cancellable" if e.not_cancellable else "-")
        out.append(f"| `{e.name}` | `{FILES[e.name]}` | {e.doc} | {drive} | {comp} |")
    return "\n".join(out)


for _name in MODULES:
    _effect = import_module(f"servo.physics.{_name}").EFFECT
    register(_effect)
    FILES[_effect.name] = f"servo/physics/{_name}.py"
del _name, _effect
NAMES = tuple(e.name for e in EFFECTS.values() if e.drive_map is not None)

__all__ = ["BASELINE_TERMS", "EFFECTS", "FILES", "MASS", "MODULES", "NAMES", "VOCABULARY", "Cancelling",
           "Concealment", "Effect", "Term", "cancel_terms", "compensator_fields", "diagnosed_by", "drive_fields",
           "command_for", "fill", "force_fields", "force_gain", "largest_forces", "markdown_table", "not_cancellable",
           "owner", "plant_values", "rates", "register", "register_term", "renamed_keys", "rest_force",
           "simulated_drive", "stage_values"]  # fmt: skip

"""The model a compensator is written from: what ``servo diagnose`` or ``servo identify``
found, as the simulated drive's physics (a ``[drive]`` section of a servo config).

The drive's section is the common language: every vocabulary term a diagnosis can name
maps onto a field of the drive (``servo.diagnose.report.drive_section``), and every
cancellable field has its mirror in ``[compensator]`` (:mod:`servo.compensate.propose`).

Sources (:func:`read_model`):

* a ``report.json`` of ``servo diagnose``: its final model (``final_model.drive``), the
  terms it holds and the recording's force unit and motion range;
* a ``summary.json`` of ``servo identify``: eq. (3)'s ``B, Fc, K, h0`` of its robust fit
  (else its paper fit).  It has no Dahl element: its Coulomb level becomes the Dahl
  asymptote (the paper's ``Ha = Fc``) over the base config's Dahl length;
* a servo config (``.toml``): its ``[drive]`` section as it stands (the exact model of a
  simulated drive).

Every source is checked before it is used: the drive's fields through the config's own
schema (:func:`servo.config.from_dict`: types, ranges, known keys), the recording's motion
and the terms' sizes as numbers; anything else is one :class:`CompensateError` line.
A diagnosis and an identification carry each fitted size with its standard deviation
(:attr:`SourceModel.sizes`), which :mod:`servo.compensate.significance` tests.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from scipy import stats

from servo import physics
from servo.config import Config, ConfigError, from_dict, load_config, to_dict
from servo.diagnose.select import ALPHA
from servo.errors import ServoError, first_line
from servo.physics import EFFECTS, VOCABULARY

#: Terms of a model no static compensator term can cancel, and what to do instead (each
#: effect's module in servo.physics says why)
NOT_CANCELLABLE = physics.not_cancellable()


class CompensateError(ServoError):
    """A source cannot be read as a model to compensate."""


@dataclass
class Size:
    """A fitted size of a model term: ``physics`` (vocabulary name), ``params`` its
    coefficients (name -> value, the force unit), ``std`` their standard deviations
    (empty: not fitted, given by a model file), ``units`` their units where known."""

    physics: str
    params: dict
    std: dict
    units: dict = field(default_factory=dict)


@dataclass
class SourceModel:
    """A model as the drive's physics: ``drive`` the ``[drive]`` fields it sets (A, m, s);
    ``physics`` the vocabulary terms it holds; ``force_unit`` "A" or "N"; ``speed_max``
    (m/s) and ``position_max`` (m, ``|x|``) the motion it was found on (None: unknown);
    ``kind`` "diagnosis", "identification" or "config"; ``position_unit`` the
    recording's, m or rad (the speeds and positions above are in it); ``sizes`` the fitted sizes with
    their standard deviations (:class:`Size`; none for a config: its values are exact)
    and ``alpha`` the level of the diagnosis they came from (two-sided, per size)."""

    source: str
    kind: str
    drive: dict
    physics: list = field(default_factory=list)
    force_unit: str = "A"
    speed_max: float | None = None
    position_max: float | None = None
    sizes: list = field(default_factory=list)
    alpha: float = ALPHA
    #: the recording's position unit: m, or rad for a rotary axis (:mod:`servo.io.units`)
    position_unit: str = "m"


def _read_json(p: Path) -> dict:
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CompensateError(f"{p}: cannot read as JSON: {first_line(exc)}") from None
    if not isinstance(doc, dict):
        raise CompensateError(f"{p}: not a report.json of servo diagnose nor a summary.json of servo identify")
    return doc


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _table(p: Path, doc: dict, key: str, required: bool = True) -> dict:
    v = doc.get(key)
    if v is None and not required:
        return {}
    if not isinstance(v, dict):
        raise CompensateError(f"{p}: {key} is {'missing' if v is None else 'not a table'} in this "
                              f"{'report' if 'final_model' in doc else 'summary'}")  # fmt: skip
    return v


def _motion(p: Path, rec: dict, key: str) -> float | None:
    """A recording's motion figure: a finite number >= 0, or None when absent."""
    v = rec.get(key)
    if v is None:
        return None
    if not _number(v) or v < 0:
        raise CompensateError(f"{p}: recording.{key} = {v!r} is not a number >= 0")
    return float(v)


def _position_unit(p: Path, v) -> str:
    from servo.io.units import POSITION_UNITS

    if v not in POSITION_UNITS:
        raise CompensateError(f"{p}: the position unit {v!r} is not one of {', '.join(POSITION_UNITS)}")
    return v


def _force_unit(p: Path, v) -> str:
    if not isinstance(v, str) or not v.strip() or len(v) > 16:
        raise CompensateError(f"{p}: the force unit {v!r} is not a unit name (A, N, ...)")
    return v.strip()


def _drive(p: Path, d) -> dict:
    """``d`` as ``[drive]`` fields, checked by the config's schema (types, ranges, keys)."""
    if not isinstance(d, dict):
        raise CompensateError(f"{p}: the final model's drive is not a table of [drive] fields")
    try:
        from_dict({"drive": d})
    except ConfigError as exc:
        raise CompensateError(f"{p}: the final model is not a valid drive: {exc}") from None
    return {k: (float(v) if _number(v) else list(map(float, v)) if isinstance(v, list) else v) for k, v in d.items()}


def _sizes(p: Path, terms) -> list[Size]:
    if not isinstance(terms, list):
        raise CompensateError(f"{p}: final_model.terms is not a list of terms")
    out = []
    for t in terms:
        if not isinstance(t, dict) or not isinstance(t.get("physics"), str):
            raise CompensateError(f"{p}: a term of final_model.terms is not a table with a physics name: {t!r:.80}")
        params, std = t.get("params", {}), t.get("std", {})
        if not isinstance(params, dict) or not isinstance(std or {}, dict):
            raise CompensateError(f"{p}: the {t['physics']} term's params and std are not tables")
        nums = {k: float(v) for k, v in params.items() if _number(v)}
        sd = {k: float(v) for k, v in (std or {}).items() if _number(v) and v >= 0}
        units = t.get("units") if isinstance(t.get("units"), dict) else {}
        units = {k: v for k, v in units.items() if isinstance(v, str)}
        out.append(Size(t["physics"], nums, {} if t.get("fixed") else sd, units))
    return out


def _from_report(p: Path, doc: dict) -> SourceModel:
    fm = doc.get("final_model")
    if not isinstance(fm, dict):
        raise CompensateError(f"{p}: no final_model in this report")
    if fm.get("drive") is None:
        raise CompensateError(f"{p}: the final model is not a drive ({fm.get('drive_note') or 'no [drive] section'}): "
                              "nothing to compensate from")  # fmt: skip
    drive = _drive(p, fm["drive"])
    rec = _table(p, doc, "recording", required=False)
    sizes = _sizes(p, fm.get("terms", []))
    settings = doc.get("settings") if isinstance(doc.get("settings"), dict) else {}
    alpha = settings.get("alpha", ALPHA)
    if not _number(alpha) or not 0 < alpha < 0.5:
        raise CompensateError(f"{p}: settings.alpha = {alpha!r} is not a level between 0 and 0.5")
    return SourceModel(str(p), "diagnosis", drive, [s.physics for s in sizes], _force_unit(p, rec.get("force_unit", "A")),
                       _motion(p, rec, "speed_max_m_s"), _motion(p, rec, "position_max_m"), sizes, float(alpha),
                       _position_unit(p, rec.get("position_unit", "m")))  # fmt: skip


#: an identification's eq. (3) parameters and the vocabulary term of each
EQ3 = physics.BASELINE_TERMS
#: the term an identification's Coulomb level is (the Dahl asymptote's effect: eq. 9
#: compensates it as the Dahl element's sliding level)
DAHL = physics.owner("drive", "Ha").name


def _from_summary(p: Path, doc: dict, base: Config) -> SourceModel:
    fits = doc.get("fits") or {}
    fit = (fits.get("robust") or fits.get("paper")) if isinstance(fits, dict) else None
    if not isinstance(fit, dict) or not isinstance(fit.get("params"), dict):
        raise CompensateError(f"{p}: no fit in this identify summary")
    q = fit["params"]
    bad = [k for k, v in q.items() if not _number(v)]
    if bad:
        raise CompensateError(f"{p}: the fit's {', '.join(bad)} is not a finite number")
    std = fit.get("std") if isinstance(fit.get("std"), dict) else {}
    Fc = float(q.get("Fc", 0.0))
    if Fc < 0 and not (_number(std.get("Fc")) and -Fc <= stats.norm.isf(ALPHA / 2) * std["Fc"]):
        raise CompensateError(f"{p}: the fit's Fc = {Fc:.4g} < 0 beyond its noise: a friction that drives the motion "
                              "is not a model to cancel")  # fmt: skip
    length = base.compensator.Ha / base.compensator.sigma  # the base config's Dahl length, m
    Ha = max(Fc, 1e-12)
    drive = dict(B=float(q.get("B", 0.0)), K=float(q.get("K", 0.0)), h0=float(q.get("h0", 0.0)), Fc=0.0, Fs=0.0,
                 Ha=Ha, sigma=Ha / length, alpha=base.compensator.alpha)  # fmt: skip
    if "J" in q:
        drive["J"] = float(q["J"])
    drive = _drive(p, drive)
    # the Coulomb level is the Dahl asymptote here: its size test is the hysteresis term's
    units = fit.get("units") if isinstance(fit.get("units"), dict) else {}
    sizes = [Size(DAHL if k == "Fc" else EQ3[k], {"Ha" if k == "Fc" else k: float(q[k])},
                  {"Ha" if k == "Fc" else k: float(std[k])} if _number(std.get(k)) else {},
                  {"Ha" if k == "Fc" else k: units[k]} if isinstance(units.get(k), str) else {})
             for k in q if k in EQ3 and k != "J"]  # fmt: skip
    return SourceModel(str(p), "identification", drive, [EQ3[k] for k in q if k in EQ3],
                       _force_unit(p, doc.get("force_unit", "A")), sizes=sizes,
                       position_unit=_position_unit(p, doc.get("position_unit", "m")))  # fmt: skip


def _from_config(p: Path) -> SourceModel:
    try:
        cfg = load_config(p)
    except ConfigError as exc:
        raise CompensateError(str(exc)) from None
    d = cfg.drive
    drive = to_dict(cfg)["drive"]
    physics = [name for name in VOCABULARY if EFFECTS[name].drive_map.in_drive(d)]
    return SourceModel(str(p), "config", drive, physics, "A", None, d.stroke)


def read_model(path: str | Path | dict, base: Config) -> SourceModel:
    """The model of ``path`` (a diagnose ``report.json``, an identify ``summary.json`` or a
    servo config ``.toml``; or the dict of such a JSON, e.g.
    ``servo.diagnose.report.build_report(D)``); ``base`` supplies what a source lacks (see
    module doc)."""
    if isinstance(path, dict):
        name = Path("<report>" if "final_model" in path else "<summary>")
        return _from_report(name, path) if "final_model" in path else _from_summary(name, path, base)
    p = Path(path)
    if not p.exists():
        raise CompensateError(f"{p}: no such file")
    if p.suffix.lower() == ".toml":
        return _from_config(p)
    doc = _read_json(p)
    if "final_model" in doc:
        return _from_report(p, doc)
    if "fits" in doc:
        return _from_summary(p, doc, base)
    raise CompensateError(f"{p} is neither a report.json of servo diagnose, a summary.json of servo identify "
                          "nor a servo config (.toml)")  # fmt: skip


__all__ = ["EQ3", "NOT_CANCELLABLE", "CompensateError", "Size", "SourceModel", "read_model"]

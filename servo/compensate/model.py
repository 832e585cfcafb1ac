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
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from servo.config import Config, ConfigError, load_config, to_dict
from servo.errors import ServoError, first_line

#: Terms of a model no static compensator term can cancel, and what to do instead.
NOT_CANCELLABLE = {
    "time_delay": "an input delay cannot be cancelled by a static term: use a predictor (a Smith predictor on "
                  "the delay) or keep the crossover well below 1/(2*pi*delay)",
    "resonance": "a flexible mode cannot be cancelled by a static term: notch it in the controller "
                 "([controller.track] notch_hz) or keep the crossover below it",
    "input_saturation": "a saturation is a limit, not a force: set [controller] current_limit at or below it so "
                        "the loop knows the room it has",
    "sensor_lag": "a low-pass on the position sensor is a lag in the loop, not a force: raise the sensor's "
                  "bandwidth (its filter's cutoff well above the crossover), or estimate the position ahead of the "
                  "filter with an observer that inverts it",
    "quantization": "the sensor's resolution is not a force: nothing to cancel (a finer encoder, or a velocity "
                    "cutoff that averages over several steps)",
}  # fmt: skip


class CompensateError(ServoError):
    """A source cannot be read as a model to compensate."""


@dataclass
class SourceModel:
    """A model as the drive's physics: ``drive`` the ``[drive]`` fields it sets (A, m, s);
    ``physics`` the vocabulary terms it holds; ``force_unit`` "A" or "N"; ``speed_max``
    (m/s) and ``position_max`` (m, ``|x|``) the motion it was found on (None: unknown);
    ``kind`` "diagnosis", "identification" or "config"."""

    source: str
    kind: str
    drive: dict
    physics: list = field(default_factory=list)
    force_unit: str = "A"
    speed_max: float | None = None
    position_max: float | None = None


def _read_json(p: Path) -> dict:
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CompensateError(f"{p}: cannot read as JSON: {first_line(exc)}") from None
    if not isinstance(doc, dict):
        raise CompensateError(f"{p}: not a report.json of servo diagnose nor a summary.json of servo identify")
    return doc


def _from_report(p: Path, doc: dict) -> SourceModel:
    fm = doc.get("final_model")
    if not isinstance(fm, dict):
        raise CompensateError(f"{p}: no final_model in this report")
    if fm.get("drive") is None:
        raise CompensateError(f"{p}: the final model is not a drive ({fm.get('drive_note') or 'no [drive] section'}): "
                              "nothing to compensate from")  # fmt: skip
    rec = doc.get("recording", {})
    physics = [t.get("physics") for t in fm.get("terms", []) if isinstance(t, dict)]
    return SourceModel(str(p), "diagnosis", dict(fm["drive"]), physics, rec.get("force_unit", "A"),
                       rec.get("speed_max_m_s"), rec.get("position_max_m"))  # fmt: skip


def _from_summary(p: Path, doc: dict, base: Config) -> SourceModel:
    fits = doc.get("fits") or {}
    fit = fits.get("robust") or fits.get("paper")
    if not isinstance(fit, dict) or not isinstance(fit.get("params"), dict):
        raise CompensateError(f"{p}: no fit in this identify summary")
    q = fit["params"]
    bad = [k for k, v in q.items() if not isinstance(v, (int, float)) or not math.isfinite(v)]
    if bad:
        raise CompensateError(f"{p}: the fit's {', '.join(bad)} is not a finite number")
    Fc = float(q.get("Fc", 0.0))
    length = base.compensator.Ha / base.compensator.sigma  # the base config's Dahl length, m
    Ha = max(Fc, 1e-12)
    drive = dict(B=float(q.get("B", 0.0)), K=float(q.get("K", 0.0)), h0=float(q.get("h0", 0.0)), Fc=0.0, Fs=0.0,
                 Ha=Ha, sigma=Ha / length, alpha=base.compensator.alpha)  # fmt: skip
    if "J" in q:
        drive["J"] = float(q["J"])
    names = {"J": "inertia", "B": "viscous_friction", "Fc": "coulomb_friction", "K": "stiffness", "h0": "offset"}
    return SourceModel(str(p), "identification", drive, [names[k] for k in q if k in names],
                       doc.get("force_unit", "A"))  # fmt: skip


def _from_config(p: Path) -> SourceModel:
    try:
        d = load_config(p).drive
    except ConfigError as exc:
        raise CompensateError(str(exc)) from None
    drive = to_dict(load_config(p))["drive"]
    physics = ["inertia", "viscous_friction", "stiffness", "offset", "hysteresis"]
    physics += [name for name, on in (
        ("coulomb_friction", d.Fc > 0), ("stribeck_friction", d.Fs > d.Fc), ("asymmetric_friction", d.b_asymmetry != 0),
        ("cogging", d.cogging > 0), ("position_dependent_gain", d.kf_linear != 0 or d.kf_quadratic != 0),
        ("resonance", len(d.mode_hz) > 0), ("time_delay", d.input_delay_s > 0), ("quantization", d.position_quantum > 0),
        ("sensor_lag", d.sensor_cutoff_hz > 0),
    ) if on]  # fmt: skip
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


__all__ = ["NOT_CANCELLABLE", "CompensateError", "SourceModel", "read_model"]

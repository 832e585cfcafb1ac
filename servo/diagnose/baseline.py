"""The model a diagnosis holds against a recording: a term set fitted on the training
part, or a model file whose parameters are held fixed.

* A term set (``--baseline J,B,Fc,K,h0``, the default, or a reduced one such as
  ``J,B``) names terms of eq. (3); they become the vocabulary terms ``inertia``,
  ``viscous_friction``, ``coulomb_friction``, ``stiffness``, ``offset`` with free
  coefficients.  Before anything else the rows are checked with
  :func:`servo.identify.check_identifiable`: a term the data cannot determine is one
  line naming it.
* A model file (``--model FILE``) is held fixed: a ``servo`` config (TOML, its
  ``[drive]`` section: the simulated drive's physics, every vocabulary term it has),
  the ``summary.json`` of ``servo identify`` (its robust fit, else its paper fit) or the
  ``report.json`` of an earlier ``servo diagnose`` (its ``final_model``).  The five
  terms of eq. (3) are always present (at zero when the file lacks them) so that a
  diagnosis can report a *correction* to any of them (the file's ``B`` is 30 % low).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from servo.config import DriveConfig, load_config
from servo.diagnose.model import GATE, Design, Model, Term
from servo.diagnose.terms import BASELINE_TERMS, VOCABULARY
from servo.physics import EFFECTS
from servo.errors import ConfigError, ServoError, first_line
from servo.identify.least_squares import check_identifiable
from servo.identify.regressors import TERMS, IdentificationError, Regression, parse_terms

DEFAULT = "J,B,Fc,K,h0"


class ModelFileError(ServoError):
    """A model file cannot be read as a model."""


def from_terms(text: str | None) -> Model:
    """Free terms of eq. (3) from ``"J,B,Fc,K,h0"`` (any subset)."""
    return Model([Term.make(BASELINE_TERMS[t]) for t in parse_terms(text or DEFAULT)])


def check_baseline(design: Design, model: Model) -> None:
    """Refuse a baseline whose free terms the training rows cannot determine (one line
    from :func:`servo.identify.check_identifiable`, naming the term)."""
    inverse = {v: k for k, v in BASELINE_TERMS.items()}
    names = [inverse[t.physics] for t in model.terms if t.free and t.physics in inverse]
    if not names:
        return
    terms = tuple(t for t in TERMS if t in names)
    w = design.train_valid
    sig = design.sig
    y, Phi, _ = design.matrix(Model([Term.make(BASELINE_TERMS[t]) for t in terms]))
    reg = Regression(terms=terms, Phi=Phi[w], y=y[w], t=sig.t_rows[w], x=sig.x_rows[w], v=sig.v_rows[w],
                     a=sig.af[sig.keep][w], dt=sig.row_dt, path="robust")  # fmt: skip
    try:
        check_identifiable(reg)
    except IdentificationError as exc:
        raise IdentificationError(f"baseline: {exc}") from None


def _fixed(physics: str, params: dict) -> Term:
    theta, coef = VOCABULARY[physics].from_physical(params)
    if GATE in params:  # a term present from an onset on (servo.diagnose.partial) keeps it
        theta = {**theta, GATE: float(params[GATE])}
    return Term.make(physics, theta, coef)


def drive_terms(d: DriveConfig) -> Model:
    """The fixed terms of a simulated drive's physics (``servo.config.DriveConfig``):
    each vocabulary term as the drive has it (:meth:`servo.physics.base.DriveMap.from_drive`)."""
    return Model([Term.make(name, theta, coef) for name in VOCABULARY for theta, coef in EFFECTS[name].drive_map.from_drive(d)])


def without_idle_inputs(model: Model, u: np.ndarray) -> Model:
    """``model`` without the input terms that leave the recorded input ``u`` as it is
    (:meth:`~servo.physics.base.SignalPath.idle`: a saturation that clips nothing, as a drive
    config's current limit does): such a term changes no row, and held in the model it
    would keep the term from being tested, so a drive config and the same fit without a
    limit (a fitted baseline, a report) would differ in what they can find."""
    return Model([t for t in model.terms if not VOCABULARY[t.physics].path.idle(t.params, u)])


def _basic_complete(model: Model) -> Model:
    """Add the missing terms of eq. (3) at zero (fixed), so corrections can be found."""
    for name in BASELINE_TERMS.values():
        if not model.has(name):
            model = model.plus(Term.make(name, coef=(0.0,)))
    return model


def from_file(path: str | Path) -> Model:
    """A fixed model from a config TOML, an identify ``summary.json`` or a diagnose
    ``report.json`` (see module doc)."""
    p = Path(path)
    if not p.exists():
        raise ModelFileError(f"model: no such file: {p}")
    if p.suffix.lower() == ".toml":
        try:
            return drive_terms(load_config(p).drive)
        except ConfigError as exc:
            raise ModelFileError(f"model: {exc}") from None
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"model: cannot read {p} as JSON: {first_line(exc)}") from None
    if isinstance(doc, dict) and "final_model" in doc:
        terms = []
        for t in doc["final_model"].get("terms", []):
            name = t.get("physics")
            if name not in VOCABULARY or VOCABULARY[name].path.kind == "sensor":
                continue
            try:
                terms.append(_fixed(name, t["params"]))
            except (KeyError, TypeError):
                raise ModelFileError(f"model: {p}: term {name!r} lacks its parameters") from None
        return _basic_complete(Model(terms))
    if isinstance(doc, dict) and "fits" in doc:
        fits = doc["fits"]
        fit = fits.get("robust") or fits.get("paper")
        if not fit or "params" not in fit:
            raise ModelFileError(f"model: {p}: no fit in this identify summary")
        return _basic_complete(Model([_fixed(BASELINE_TERMS[k], {k: v}) for k, v in fit["params"].items()
                                      if k in BASELINE_TERMS and math.isfinite(v)]))  # fmt: skip
    raise ModelFileError(f"model: {p} is neither a servo config (.toml), an identify summary.json nor a diagnose report.json")


def model_is_excited(design: Design, model: Model) -> None:
    """The recording must move: a constant position or input is refused."""
    sig = design.sig
    if np.ptp(sig.x) == 0:
        raise IdentificationError("nothing excited: the position is constant")
    if np.ptp(sig.u) == 0:
        raise IdentificationError("nothing excited: the input is constant")


__all__ = ["DEFAULT", "ModelFileError", "check_baseline", "drive_terms", "from_file", "from_terms", "model_is_excited",
           "without_idle_inputs"]

"""Identification of eq. (4) from a :class:`~servo.io.recording.Recording` in one call."""
from __future__ import annotations

from dataclasses import dataclass

from servo.identify.least_squares import LSResult, least_squares
from servo.identify.regressors import (
    TERMS, IdentificationError, Regression, RobustSettings, paper_regression, robust_regression,
)  # fmt: skip
from servo.io.recording import Recording

PATHS = ("robust", "paper")


@dataclass(frozen=True)
class Identification:
    """A regression and its least-squares fit."""

    regression: Regression
    fit: LSResult

    def __repr__(self) -> str:
        f = self.fit
        terms = ", ".join(f"{t} = {p:.4g}" for t, p in zip(f.terms, f.params))
        return f"<Identification ({self.regression.path} path): {terms}; error {f.rel_error_pct:.3g} %, {f.n_rows} rows>"

    def as_dict(self, force_unit: str = "A", position_unit: str = "m") -> dict:
        r = self.regression
        return {"path": r.path, "settings": r.settings, "row_dt_s": r.dt, **self.fit.as_dict(force_unit, position_unit)}


def identify(rec: Recording, path: str = "robust", terms=TERMS, settings: RobustSettings | None = None,
             force_lag_s: float = 0.0) -> Identification:  # fmt: skip
    """Least squares of eq. (4) on ``rec`` (``t`` s, ``x`` m, ``u`` force, ``v`` m/s).

    ``path``: ``"robust"`` (inverse dynamics, :func:`robust_regression` with
    ``settings``) or ``"paper"`` (measured velocity, backward-difference acceleration:
    needs ``rec.v``).  ``force_lag_s``: how late the recorded force acts (see
    :mod:`servo.identify.regressors`).  A fit whose inertia ``J`` is not positive is
    refused (:class:`IdentificationError`): no drive has one.
    """
    if path == "robust":
        reg = robust_regression(rec.t, rec.x, rec.u, rec.dt, terms, settings, force_lag_s)
    elif path == "paper":
        if rec.v is None:
            raise IdentificationError("the paper's path needs a measured velocity column v; map one with --columns v=NAME or use --path robust")
        reg = paper_regression(rec.t, rec.x, rec.u, rec.v, rec.dt, terms, force_lag_s)
    else:
        raise IdentificationError(f"unknown derivative path {path!r} (choose {' or '.join(PATHS)})")
    fit = least_squares(reg)
    if "J" in fit.terms and not fit["J"] > 0:  # u and x swapped, u constant: "J = -3.3e-19, relative error 0.0000 %"
        raise IdentificationError(f"the {path} path's inertia J = {fit['J']:.3g} is not positive: the force does not "
                                  "accelerate the position as eq. (4) says (u and x swapped, a sign, a force that does "
                                  "not drive this axis?); if the recording does not excite the inertia, switch J off")  # fmt: skip
    return Identification(reg, fit)


__all__ = ["PATHS", "Identification", "identify"]

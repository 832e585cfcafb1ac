"""A model fitted on the training rows: coefficients, uncertainties, residuals, errors.

The free coefficients are the least-squares solution on the training rows that are
usable (:attr:`servo.diagnose.model.Design.train_valid`).  Their standard deviations
are the ordinary least-squares figure inflated by the residual's integrated
autocorrelation time ``tau`` (the rows are filtered, so they are not independent):
``cov = tau * s^2 * (Z'Z)^-1``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servo.diagnose.model import Design, Model
from servo.diagnose.select import integrated_time, solve
from servo.diagnose.terms import VOCABULARY
from servo.physics import EFFECTS, MASS


@dataclass
class Fit:
    """``model`` with ``coefs[i]`` / ``std[i]`` the coefficients of ``model.terms[i]``
    (fixed ones with zero std); ``y`` (m,) its target rows; ``residual`` (m,) target minus
    fit on every row; ``tau`` the residual's integrated autocorrelation time;
    ``theta_std[i]`` the std of term ``i``'s nonlinear parameters (if known); ``cov``
    (p, p) the covariance of the free coefficients in the order of the free columns
    (``tau * s^2 * (Z'Z)^-1``, ``s^2`` the residual variance of the fitted rows)."""

    model: Model
    coefs: list
    std: list
    y: np.ndarray
    residual: np.ndarray
    tau: float
    theta_std: list
    cov: np.ndarray

    def term_params(self, i: int) -> dict:
        """Reported parameters of term ``i`` (:meth:`Physics.physical`)."""
        t = self.model.terms[i]
        return VOCABULARY[t.physics].physical(t.params, self.coefs[i])

    def term_std(self, i: int) -> dict:
        t = self.model.terms[i]
        phys = VOCABULARY[t.physics]
        out = {n: float(s) for n, s in zip(phys.coefs, self.std[i])}
        out.update(self.theta_std[i])
        out.update(phys.judging.std_extra(self.term_params(i), out))
        return out

    def mass(self, default: float | None = 0.0) -> float | None:
        """The moving mass ``J`` (:data:`servo.physics.MASS`; ``default`` without one)."""
        return self.combined().get(MASS, {}).get("J", default)

    def mass_std(self) -> float | None:
        """The std of a fitted mass (0 when the model holds it fixed or lacks it)."""
        i = next((i for i, t in enumerate(self.model.terms) if t.physics == MASS), None)
        return self.term_std(i).get("J") if i is not None and self.model.terms[i].free else 0.0

    def combined(self) -> dict:
        """Physics name -> reported parameters, a fixed term and its correction added
        (a model file's ``B`` plus a found ``viscous_friction`` correction)."""
        out: dict = {}
        for i, t in enumerate(self.model.terms):
            p = self.term_params(i)
            if t.physics in out and not VOCABULARY[t.physics].thetas:
                out[t.physics] = {k: out[t.physics][k] + p[k] for k in p}
            else:
                out[t.physics] = p
        return out

    def drive(self) -> dict:
        """The model as the simulated drive's ``[drive]`` fields (force unit, m, s), each
        term's own (:meth:`servo.physics.base.DriveMap.to_drive`), the ``absent``
        values of the terms it lacks; not validated (a fitted ``B`` may be negative)."""
        P = self.combined()
        d: dict = {}
        maps = [EFFECTS[name].drive_map for name in VOCABULARY]  # each term's effect's
        for m in maps:
            d.update(m.absent)
        for m in maps:  # vocabulary order: a Stribeck term after the Coulomb one
            if m.name in P:
                d.update(m.to_drive(P, self))
        return d

    def contribution(self, design: Design, i: int) -> np.ndarray:
        """Rows (m,) of term ``i``'s part of the force (zero for an input term)."""
        t = self.model.terms[i]
        if VOCABULARY[t.physics].path.kind != "column":
            return np.zeros(design.sig.m)
        return design.term_rows(t, self.model) @ np.asarray(self.coefs[i])


def fit_model(design: Design, model: Model, theta_std: list | None = None, rows: np.ndarray | None = None) -> Fit:
    """Least squares of the free coefficients of ``model`` on ``rows`` (default: the
    training rows that are usable)."""
    w = design.train_valid if rows is None else rows
    y, Phi, _ = design.matrix(model)
    Z, yy = Phi[w], y[w]
    c = solve(Z.T @ Z, Z.T @ yy)
    r = y - Phi @ c
    rw = r[w]
    first, last = np.flatnonzero(w)[[0, -1]]
    tau = integrated_time(np.where(w, r, 0.0)[first : last + 1])
    p = Phi.shape[1]
    s2 = float(rw @ rw) / max(rw.size - p, 1)
    if p:
        G = Z.T @ Z
        d = np.sqrt(np.clip(np.diag(G), 1e-300, None))
        cov = np.linalg.pinv(G / np.outer(d, d)) / np.outer(d, d) * (s2 * tau)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    else:
        cov, sd = np.zeros((0, 0)), np.zeros(0)
    coefs, std, j = [], [], 0
    for t in model.terms:
        phys = VOCABULARY[t.physics]
        if phys.path.kind != "column":
            coefs.append(())
            std.append(())
        elif t.free:
            k = len(phys.coefs)
            coefs.append(tuple(float(v) for v in c[j : j + k]))
            std.append(tuple(float(v) for v in sd[j : j + k]))
            j += k
        else:
            coefs.append(t.coef)
            std.append(tuple(0.0 for _ in t.coef))
    ts = list(theta_std) if theta_std is not None else [{} for _ in model.terms]
    ts += [{} for _ in range(len(model.terms) - len(ts))]
    return Fit(model, coefs, std, y, r, tau, ts, cov)


def force_error_pct(design: Design, fit: Fit, rows: np.ndarray) -> float:
    """Relative force error on ``rows`` (%): ``100*||residual||/||recorded force||`` (the
    aligned, filtered, decimated input of the recording)."""
    y0 = design.target_raw(Model())
    return float(100 * np.linalg.norm(fit.residual[rows]) / max(np.linalg.norm(y0[rows]), 1e-300))


__all__ = ["Fit", "fit_model", "force_error_pct"]

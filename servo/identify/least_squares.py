"""Least squares on the regressor of eq. (4): estimates, their standard deviations, the
condition number and the relative error (Gong et al. 2002, eq. 5).

    p_hat = (Phi' Phi)^-1 Phi' y                                (5)

solved with :func:`scipy.linalg.lstsq` (an SVD, not the normal equations).  With
``e = y - Phi p_hat`` over ``m`` rows and ``p`` parameters::

    sigma_e^2    = ||e||^2 / (m - p)
    std(p_hat_i) = sigma_e * sqrt(((Phi' Phi)^-1)_ii)
    rel. error   = 100 * ||e|| / ||y||   (%)

The standard deviations assume white residuals (the textbook OLS figure; the EMPS
reference reports the same).  Before solving, :func:`check_identifiable` refuses data that
cannot determine a requested term and says which and why: no velocity reversal (``Fc``
is then the offset ``h0`` in disguise), no motion (``K``), no acceleration (``J``), or a
rank-deficient regressor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

from servo.identify.regressors import COLUMN, IdentificationError, Regression, units

#: A regressor whose column-normalised condition number exceeds this is rank deficient.
MAX_SCALED_CONDITION = 1e8
#: ``Fc`` needs at least this fraction of the rows moving in each direction.
MIN_DIRECTION_FRACTION = 0.02


@dataclass(frozen=True)
class LSResult:
    """Least-squares estimates of the active ``terms``.

    ``params``, ``std``: (p,) estimates and standard deviations (units of :data:`UNITS`);
    ``y_hat``, ``residual``: (m,) fitted force and ``y - y_hat``; ``sigma_e``: residual
    standard deviation; ``rel_error_pct``: ``100*||y - y_hat||/||y||``; ``cond``: condition
    number of the regressor as built (what the EMPS reference reports); ``cond_scaled``:
    with every column scaled to unit norm (what decides identifiability).
    """

    terms: tuple[str, ...]
    params: np.ndarray
    std: np.ndarray
    y_hat: np.ndarray
    residual: np.ndarray
    sigma_e: float
    rel_error_pct: float
    cond: float
    cond_scaled: float
    n_rows: int

    @property
    def rel_std_pct(self) -> np.ndarray:
        """Standard deviation relative to each estimate, % (inf for a zero estimate)."""
        with np.errstate(divide="ignore"):
            return 100.0 * self.std / np.abs(self.params)

    def __getitem__(self, term: str) -> float:
        return float(self.params[self.terms.index(term)])

    def as_dict(self, force_unit: str = "A", position_unit: str = "m") -> dict:
        """JSON-able summary (no per-row arrays); units for forces in ``force_unit`` and
        positions in ``position_unit``."""
        return {
            "terms": list(self.terms),
            "params": {t: float(p) for t, p in zip(self.terms, self.params)},
            "std": {t: float(s) for t, s in zip(self.terms, self.std)},
            "rel_std_pct": {t: float(s) for t, s in zip(self.terms, self.rel_std_pct)},
            "units": {t: units(force_unit, position_unit)[t] for t in self.terms},
            "rel_error_pct": self.rel_error_pct,
            "sigma_e": self.sigma_e,
            "cond": self.cond,
            "cond_scaled": self.cond_scaled,
            "n_rows": self.n_rows,
        }


def check_identifiable(reg: Regression) -> None:
    """Raise :class:`IdentificationError` naming the term the data cannot determine."""
    m, p = reg.Phi.shape
    if m < 2 * p:
        raise IdentificationError(f"{m} rows for {p} parameters: too few to identify (need at least {2 * p})")
    if not np.all(np.isfinite(reg.Phi)) or not np.all(np.isfinite(reg.y)):
        raise IdentificationError("the regressor or the force has NaN/inf values")
    if not np.any(reg.y):
        raise IdentificationError("nothing to fit: the force is zero in every row")
    motion = np.ptp(reg.x)
    if motion <= 1e-9 * np.max(np.abs(reg.x)) or not np.any(reg.v):
        raise IdentificationError("nothing excited: the position does not change, so no term of eq. (4) but h0 can be identified")
    if "J" in reg.terms and not np.any(reg.column("J")):
        raise IdentificationError("J is not identifiable: the acceleration is zero in every row (switch J off)")
    if "Fc" in reg.terms:
        s = np.sign(reg.v)
        up, down = np.mean(s > 0), np.mean(s < 0)
        if min(up, down) < MIN_DIRECTION_FRACTION:
            raise IdentificationError(
                f"Fc is not identifiable: the velocity hardly ever reverses ({100 * up:.1f} % of rows moving +, "
                f"{100 * down:.1f} % moving -); excite both directions or switch Fc off"
            )
    scale = np.linalg.norm(reg.Phi, axis=0)
    for name, sc in zip(reg.terms, scale):
        if sc == 0.0:
            raise IdentificationError(f"{name} is not identifiable: its column {COLUMN[name]} is zero in every row")
    u, sv, vt = np.linalg.svd(reg.Phi / scale, full_matrices=False)
    cond = sv[0] / sv[-1] if sv[-1] > 0 else np.inf
    if cond > MAX_SCALED_CONDITION:
        null = vt[-1]
        involved = [n for n, c in zip(reg.terms, null) if abs(c) > 0.2]
        hint = ""
        if "K" in involved:
            hint = f" (the position spans only {motion:.3g} m: too little motion for K)"
        raise IdentificationError(
            f"the regressor is rank deficient (scaled condition number {cond:.3g}): {', '.join(involved)} "
            f"cannot be told apart by these data{hint}; switch one of them off"
        )


def least_squares(reg: Regression, check: bool = True) -> LSResult:
    """Eq. (5) on ``reg``: estimates, standard deviations, conditioning, relative error."""
    if check:
        check_identifiable(reg)
    Phi, y = reg.Phi, reg.y
    m, p = Phi.shape
    params, _, rank, sv = linalg.lstsq(Phi, y, lapack_driver="gelsd")
    if rank < p:
        raise IdentificationError(f"the regressor has rank {rank} < {p} parameters")
    y_hat = Phi @ params
    e = y - y_hat
    sigma_e = float(np.linalg.norm(e) / np.sqrt(max(m - p, 1)))
    # (Phi' Phi)^-1 through the SVD: V diag(1/s^2) V'
    _, s, vt = np.linalg.svd(Phi, full_matrices=False)
    cov_diag = np.sum((vt / s[:, None]) ** 2, axis=0)
    std = sigma_e * np.sqrt(cov_diag)
    scale = np.linalg.norm(Phi, axis=0)
    ss = np.linalg.svd(Phi / scale, compute_uv=False)
    return LSResult(
        terms=reg.terms, params=params, std=std, y_hat=y_hat, residual=e, sigma_e=sigma_e,
        rel_error_pct=float(100.0 * np.linalg.norm(e) / np.linalg.norm(y)),
        cond=float(s[0] / s[-1]), cond_scaled=float(ss[0] / ss[-1]), n_rows=m,
    )  # fmt: skip


__all__ = ["LSResult", "check_identifiable", "least_squares"]

"""Fit of the simplified Dahl hysteresis (eq. 6-7) to a current-vs-position loop.

Model of the current measured while the arm moves slowly near a turnaround (paper
section IV-A, Fig. 3)::

    u_hat_k = H(x_0..x_k; sigma, Ha, alpha) + K*x_k + c

``H`` is the Dahl estimate run sample by sample over the recorded positions and
velocity directions (:func:`kernels.hysteresis.dahl_trace`, the compensator's own
estimator), ``K`` a known bias stiffness (default 0) and ``c`` an offset (the bias
``h0`` plus whatever current holds the arm).  Inertia and viscous friction are left out:
the experiment runs slowly enough for them to be negligible (the docs give the figure).

``sigma``, ``Ha``, ``alpha`` and ``c`` are found by :func:`scipy.optimize.least_squares`
(trust-region reflective, bounds ``sigma, Ha > 0``, ``0.1 <= alpha <= 10``) on the
simulated response; standard deviations come from the Jacobian at the solution,
``cov = s^2 (J'J)^-1`` with ``s^2 = ||r||^2/(n - p)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares as scipy_least_squares

from kernels.hysteresis import dahl_trace
from servo.identify.regressors import IdentificationError

NAMES = ("sigma", "Ha", "alpha", "c")
UNITS = {"sigma": "A/m", "Ha": "A", "alpha": "-", "c": "A"}


MAX_TRUSTED_ERROR_PCT = 50.0
"""A Dahl fit that leaves more of the loop's variation unexplained is not reported as a
result (:meth:`DahlFit.problems`); the simulated drive's fits leave a few percent."""


@dataclass(frozen=True)
class DahlFit:
    """Fitted Dahl parameters.

    ``params``/``std``: name -> value (:data:`UNITS`; ``alpha`` absent from ``std`` when
    held fixed); ``u_hat``, ``H``, ``residual``: (n,) model current, its Dahl part and
    ``u - u_hat`` (A); ``rel_error_pct``: ``100*||u - u_hat||/||u - mean(u)||`` (of the
    loop's variation, not of the offset); ``saturation``: ``max|H|/Ha`` reached (below
    ~0.6 the data hardly see the asymptote, so ``Ha`` and ``sigma`` trade off);
    ``dahl_length``: ``Ha/sigma`` (m), the distance over which the pivot goes from
    sticking to sliding.
    """

    params: dict
    std: dict
    u_hat: np.ndarray
    H: np.ndarray
    residual: np.ndarray
    rel_error_pct: float
    saturation: float
    nfev: int

    @property
    def dahl_length(self) -> float:
        return self.params["Ha"] / self.params["sigma"]

    def problems(self) -> list[str]:
        """Why this fit cannot be trusted, one phrase each (empty: no reason found):
        parameters whose uncertainty is not finite (not identifiable from these data), or
        a model that explains less than half of the loop's variation."""
        out = []
        bad = [k for k, v in self.std.items() if not np.isfinite(v)]
        if bad:
            out.append(f"{', '.join(bad)} not identifiable from these data (infinite uncertainty)")
        if not self.rel_error_pct <= MAX_TRUSTED_ERROR_PCT:
            out.append(f"the Dahl model leaves {self.rel_error_pct:.1f} % of the loop's variation unexplained")
        return out

    def as_dict(self) -> dict:
        return {
            "params": dict(self.params), "std": dict(self.std),
            "units": {k: UNITS[k] for k in self.params}, "rel_error_pct": self.rel_error_pct,
            "saturation": self.saturation, "dahl_length_m": self.dahl_length, "nfev": self.nfev,
        }  # fmt: skip


def dahl_response(x, v, sigma: float, Ha: float, alpha: float, deadband: float = 0.0, H0: float = 0.0) -> np.ndarray:
    """The Dahl estimate (A) along positions ``x`` (m), directions from ``v`` (m/s)."""
    x = np.ascontiguousarray(x, dtype=float)
    v = np.ascontiguousarray(v, dtype=float)
    out = np.empty_like(x)
    dahl_trace(x, v, float(deadband), float(sigma), float(Ha), float(alpha), float(H0), out)
    return out


def fit_dahl(x, v, u, deadband: float = 0.0, fit_alpha: bool = True, alpha: float = 1.0, K: float = 0.0,
             guess: dict | None = None) -> DahlFit:  # fmt: skip
    """Fit ``sigma``, ``Ha`` (and ``alpha`` unless ``fit_alpha`` is False, then held at
    ``alpha``) and the offset ``c`` to the current ``u`` (A) measured along ``x`` (m)
    with velocity ``v`` (m/s; its sign with ``deadband`` gives the direction).

    ``guess``: starting values (default from the data: ``Ha`` half the current's range,
    ``sigma`` such that the loop spans four Dahl lengths, ``alpha = 1``, ``c`` the
    mid-range current).
    """
    x, v, u = (np.ascontiguousarray(z, dtype=float).ravel() for z in (x, v, u))
    if not (x.shape == v.shape == u.shape):
        raise IdentificationError("x, v and u must have the same length")
    s = np.sign(v) * (np.abs(v) > deadband)
    if np.count_nonzero(np.diff(s[s != 0])) < 2:
        raise IdentificationError("the Dahl fit needs velocity reversals (turnarounds): the motion does not reverse")
    span, u_span = np.ptp(x), np.ptp(u)
    if span == 0.0 or u_span == 0.0:
        raise IdentificationError("nothing excited: the position or the current does not change")
    x0 = x - np.mean(x)  # the offset is fitted; keep positions centred for conditioning
    g = {"Ha": u_span / 2, "sigma": 4 * (u_span / 2) / span, "alpha": alpha, "c": 0.5 * (u.max() + u.min())}
    g.update(guess or {})
    u_scale = u_span

    def unpack(p):
        sigma, Ha = np.exp(p[0]), np.exp(p[1])
        a = p[2] if fit_alpha else alpha
        return sigma, Ha, a, p[-1] * u_scale

    def model(p):
        sigma, Ha, a, c = unpack(p)
        H = dahl_response(x0, v, sigma, Ha, a, deadband)
        return H, H + K * x + c

    def resid(p):
        return (model(p)[1] - u) / u_scale

    p0 = [np.log(g["sigma"]), np.log(g["Ha"])] + ([g["alpha"]] if fit_alpha else []) + [g["c"] / u_scale]
    lo = [-np.inf, -np.inf] + ([0.1] if fit_alpha else []) + [-np.inf]
    hi = [np.inf, np.inf] + ([10.0] if fit_alpha else []) + [np.inf]
    sol = scipy_least_squares(resid, p0, bounds=(lo, hi), method="trf", x_scale="jac", diff_step=1e-6)
    sigma, Ha, a, c = unpack(sol.x)
    H, u_hat = model(sol.x)
    r = u - u_hat
    n, p = u.size, sol.x.size
    s2 = np.sum(sol.fun**2) / max(n - p, 1)
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        sd = np.full(p, np.inf)
    # back to parameter units: d(sigma) = sigma*d(log sigma)
    std = {"sigma": sigma * sd[0], "Ha": Ha * sd[1]}
    if fit_alpha:
        std["alpha"] = sd[2]
    std["c"] = sd[-1] * u_scale
    params = {"sigma": sigma, "Ha": Ha, "alpha": a, "c": c}
    return DahlFit(
        params={k: float(params[k]) for k in NAMES}, std={k: float(val) for k, val in std.items()},
        u_hat=u_hat, H=H, residual=r, rel_error_pct=float(100 * np.linalg.norm(r) / np.linalg.norm(u - u.mean())),
        saturation=float(np.max(np.abs(H)) / Ha), nfev=int(sol.nfev),
    )  # fmt: skip


__all__ = ["DahlFit", "dahl_response", "fit_dahl"]

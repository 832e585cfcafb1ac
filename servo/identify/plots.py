"""Figures of an identification: estimated vs measured acceleration (paper Fig. 5) and the
force fit with its residual."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from servo.identify.identification import Identification
from servo.io.plotting import finish, subplots


def estimated_acceleration(ident: Identification) -> np.ndarray:
    """Acceleration (m/s^2) the identified model predicts from the force: eq. (3) solved
    for ``x''``, ``(y - B*x' - Fc*sgn(x') - K*x - h0)/J``, per row (needs ``J``)."""
    reg, fit = ident.regression, ident.fit
    j = reg.terms.index("J")
    others = np.delete(reg.Phi, j, axis=1) @ np.delete(fit.params, j)
    return (reg.y - others) / fit.params[j]


def _zoom(t: np.ndarray, span: float) -> np.ndarray:
    """Rows of a window of ``span`` s in the middle of the record."""
    mid = 0.5 * (t[0] + t[-1])
    return (t >= mid - span / 2) & (t <= mid + span / 2)


def plot_acceleration(ident: Identification, path: Path | None = None, title: str = "",
                      zoom_s: float | None = None, position_unit: str = "m") -> Figure:
    """Paper Fig. 5: the acceleration estimated from the force by the identified model
    against the measured one (the regressor's ``x''`` column), whole record and a zoom of
    ``zoom_s`` s (default a tenth of the record), in ``position_unit``/s^2.  Written to
    ``path`` when given."""
    reg = ident.regression
    a_meas = reg.column("J")
    a_hat = estimated_acceleration(ident)
    t = reg.t
    fig, ax = subplots(2, 1, figsize=(10, 7))
    ax[0].plot(t, a_meas, color="k", lw=1.0, label="measured x''")
    ax[0].plot(t, a_hat, color="tab:red", lw=0.8, ls="--", label="estimated from the force, eq. (3)")
    m = _zoom(t, zoom_s or (t[-1] - t[0]) / 10)
    ax[1].plot(t[m], a_meas[m], color="k", lw=1.2, marker=".", ms=3, label="measured x''")
    ax[1].plot(t[m], a_hat[m], color="tab:red", lw=1.0, ls="--", marker=".", ms=3, label="estimated")
    err = 100 * np.linalg.norm(a_meas - a_hat) / np.linalg.norm(a_meas)
    ax[0].set_title(title or f"Estimated vs measured acceleration ({reg.path} path): difference {err:.2g} % RMS")
    ax[1].set_title("zoom")
    for x in ax:
        x.set_ylabel(f"acceleration ({position_unit}/s^2)")
        x.grid(alpha=0.3)
        x.legend(fontsize=8, loc="upper right")
    ax[1].set_xlabel("time (s)")
    return finish(fig, path)


def plot_force_fit(ident: Identification, path: Path | None = None, force_unit: str = "A", title: str = "") -> Figure:
    """Force of the recording (after the path's filtering) vs the fitted force, and the
    residual, over time (``force_unit``: the recording's, ``A`` drawn in mA).  Written to
    ``path`` when given."""
    reg, fit = ident.regression, ident.fit
    scale, unit = (1e3, "m" + force_unit) if force_unit == "A" else (1.0, force_unit)
    fig, ax = subplots(2, 1, figsize=(10, 7), sharex=True)
    ax[0].plot(reg.t, reg.y * scale, color="tab:blue", lw=1.2, label="measured force")
    ax[0].plot(reg.t, fit.y_hat * scale, color="tab:red", lw=0.8, ls="--", label="fit, eq. (4)")
    ax[1].plot(reg.t, fit.residual * scale, color="k", lw=0.6, label="residual")
    ax[0].set_title(title or f"Force fit ({reg.path} path): relative error {fit.rel_error_pct:.3g} %, "
                    f"condition number {fit.cond:.3g}")  # fmt: skip
    ax[0].set_ylabel(f"force ({unit})")
    ax[1].set_ylabel(f"residual ({unit})")
    ax[1].set_xlabel("time (s)")
    for x in ax:
        x.grid(alpha=0.3)
        x.legend(fontsize=8, loc="upper right")
    return finish(fig, path)


__all__ = ["estimated_acceleration", "plot_acceleration", "plot_force_fit"]

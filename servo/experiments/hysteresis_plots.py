"""Figures of the hysteresis experiments: the small loop with its Dahl fit (paper Fig. 3)
and the large loop with its average slope (Fig. 4)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from servo.identify.dahl_fit import DahlFit
from servo.identify.least_squares import LSResult
from servo.io.plotting import figure, finish, subplots


def plot_small_loop(t, x, u, fit: DahlFit, path: Path | None = None, title: str = "") -> Figure:
    """Current vs position, measured (solid) and Dahl model (dotted), and both over time
    (``t`` s, ``x`` m, ``u`` A, arrays of one length).  Written to ``path`` when given."""
    p = fit.params
    fig = figure(figsize=(12, 5.5))
    fig.subplots_adjust(wspace=0.3)
    ax0 = fig.add_subplot(1, 2, 1)
    ax0.plot(x * 1e6, u * 1e3, color="k", lw=1.0, label="experiment (simulated drive)")
    ax0.plot(x * 1e6, fit.u_hat * 1e3, color="tab:red", lw=1.0, ls=":", label="Dahl model, eq. (6-7)")
    ax0.set_xlabel("position (um)")
    ax0.set_ylabel("VCM current (mA)")
    ax0.set_title(title or "Hysteresis loop: experiment vs model")
    ax0.legend(fontsize=8, loc="upper left")
    ax0.grid(alpha=0.3)
    ax1 = fig.add_subplot(2, 2, 2)
    ax1.plot(t, u * 1e3, color="k", lw=0.8, label="measured current")
    ax1.plot(t, fit.u_hat * 1e3, color="tab:red", lw=0.8, ls=":", label="model")
    ax1.set_ylabel("current (mA)")
    ax1.legend(fontsize=8, loc="upper right")
    ax1.grid(alpha=0.3)
    ax1.set_title(f"sigma = {p['sigma']:.4g} A/m, Ha = {p['Ha'] * 1e3:.4g} mA, alpha = {p['alpha']:.3g}, "
                  f"c = {p['c'] * 1e3:.4g} mA", fontsize=9)  # fmt: skip
    ax2 = fig.add_subplot(2, 2, 4, sharex=ax1)
    ax2.plot(t, fit.residual * 1e3, color="tab:gray", lw=0.6, label=f"residual ({fit.rel_error_pct:.2g} % of the loop)")
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("residual (mA)")
    ax2.legend(fontsize=8, loc="upper right")
    ax2.grid(alpha=0.3)
    return finish(fig, path)


def plot_large_loop(x, u, slope: LSResult, path: Path | None = None, title: str = "") -> Figure:
    """Large-range current vs position with the average line ``K*x + h0`` (eq. 11) and the
    two sliding branches ``K*x + h0 +- Fc`` (``x`` m, ``u`` A).  Written to ``path`` when given."""
    K, h0, Fc = slope["K"], slope["h0"], slope["Fc"]
    xs = np.linspace(x.min(), x.max(), 50)
    fig, ax = subplots(figsize=(8, 5.5))
    ax.plot(x * 1e3, u * 1e3, color="k", lw=0.8, label="experiment (simulated drive)")
    ax.plot(xs * 1e3, (K * xs + h0) * 1e3, color="tab:blue", lw=1.5,
            label=f"average: K*x + h0, K = {K:.4g} A/m, h0 = {h0 * 1e3:.4g} mA")  # fmt: skip
    for sgn in (1, -1):
        ax.plot(xs * 1e3, (K * xs + h0 + sgn * Fc) * 1e3, color="tab:blue", lw=0.8, ls="--",
                label=f"K*x + h0 +- Fc, Fc = {Fc * 1e3:.4g} mA" if sgn == 1 else None)  # fmt: skip
    lo, hi = np.percentile(u, [1, 99]) * 1e3
    pad = 0.3 * (hi - lo)
    ax.set_ylim(lo - pad, hi + pad)  # the turnaround spikes (inertia) would dwarf the loop
    ax.set_xlabel("position (mm)")
    ax.set_ylabel("VCM current (mA)")
    ax.set_title(title or "Hysteresis loop in large range and its average slope (eq. 11)")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    return finish(fig, path)


__all__ = ["plot_large_loop", "plot_small_loop"]

"""Bode plots overlaying the input current levels (paper Fig. 7-10)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from servo.experiments.bode import Sweep
from servo.io.plotting import colors as colormap_colors
from servo.io.plotting import finish, subplots


def plot_bode(sweeps: list[Sweep], path: Path | None = None, title: str = "", band: float | None = None) -> Figure:
    """Magnitude (dB, m/A) and phase (deg) of each sweep, one colour per level; the
    double-integrator reference ``1/(J*w^2)`` is not drawn (the plot shows measurements only).  Written to ``path`` when given."""
    fig, ax = subplots(2, 1, figsize=(9, 7.5), sharex=True)
    colors = colormap_colors("viridis", np.linspace(0, 0.9, len(sweeps)))
    for s, c in zip(sweeps, colors):
        ax[0].semilogx(s.f, s.mag_db, color=c, marker=".", ms=4, lw=1.2, label=f"{s.level * 1e3:g} mA")
        ax[1].semilogx(s.f, s.phase_deg, color=c, marker=".", ms=4, lw=1.2)
    if band and band < sweeps[0].f[-1]:
        for x in ax:
            x.axvspan(sweeps[0].f[0], band, color="0.93", zorder=0)
    ax[0].set_ylabel("|X/U| (dB re 1 m/A)")
    ax[1].set_ylabel("phase (deg)")
    ax[1].set_xlabel("frequency (Hz)")
    ax[0].set_title(title)
    ax[0].legend(title="input current level", fontsize=8)
    for x in ax:
        x.grid(alpha=0.3, which="both")
    return finish(fig, path)


__all__ = ["plot_bode"]

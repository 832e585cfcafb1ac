"""Figures of ``servo loop``: the open loop against its design, and the sensitivities.

Measured points are markers (one colour per run), designs are lines; the crossover of
each is marked on the magnitude, the phase margin on the phase.  Every function
returns its :class:`~matplotlib.figure.Figure` and writes it only when given a path.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from servo.io.plotting import colors as colormap_colors
from servo.io.plotting import finish, subplots
from servo.loop.design import LoopDesign
from servo.loop.measure import LoopMeasurement

_DESIGN_STYLE = (("-", "k"), ("--", "0.45"), (":", "C3"), ("-.", "C2"))  # (linestyle, colour)


def _db(h) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return 20 * np.log10(np.abs(h))


def _phase(h) -> np.ndarray:
    """Unwrapped phase (deg) shifted so the loop's phase near crossover sits in (-360, 0]."""
    ph = np.degrees(np.unwrap(np.angle(h)))
    i = int(np.argmin(np.abs(np.abs(h) - 1.0)))
    return ph - 360.0 * np.ceil(ph[i] / 360.0)


def _run_colors(runs):
    return colormap_colors("viridis", np.linspace(0.0, 0.85, max(len(runs), 1)))


def plot_loop(runs: list[LoopMeasurement], designs: list[LoopDesign], margins: dict | None = None,
              path: str | Path | None = None, title: str = "") -> Figure:  # fmt: skip
    """Bode plot of the open loop ``L`` (broken at the controller output): each run's
    measured points, each design's line; crossover and phase margin of each marked when
    ``margins`` (``{label: margins dict}``, labels of the runs and designs) is given."""
    fig, ax = subplots(2, 1, figsize=(9, 7.5), sharex=True)
    margins = margins or {}
    for d, style in zip(designs, _DESIGN_STYLE):
        L = d.L
        ls, c = style
        ax[0].semilogx(d.f_hz, _db(L), ls=ls, color=c, lw=1.2, label=f"design: {d.model}")
        ax[1].semilogx(d.f_hz, _phase(L), ls=ls, color=c, lw=1.2)
        _mark(ax, margins.get(f"design: {d.model}"), c, text=False)
    for r, c in zip(runs, _run_colors(runs)):
        L = r.value("L")
        ax[0].semilogx(r.f, _db(L), "o", color=c, ms=5, mfc="none", label=f"measured: {r.label}")
        ax[1].semilogx(r.f, _phase(L), "o", color=c, ms=5, mfc="none")
        _mark(ax, margins.get(r.label), c)
    ax[0].axhline(0.0, color="0.5", lw=0.8)
    ax[1].axhline(-180.0, color="0.5", lw=0.8)
    ax[0].set_ylabel("|L| (dB)")
    ax[1].set_ylabel("phase of L (deg)")
    ax[1].set_xlabel("frequency (Hz)")
    ax[0].set_title(title or "Open loop L = -U_pi/U_n (broken at the controller output)")
    ax[0].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3, which="both")
    return finish(fig, path)


def _mark(ax, m: dict | None, color, text: bool = True) -> None:
    if not m or m.get("crossover_hz") is None:
        return
    fc, pm = m["crossover_hz"], m["phase_margin_deg"]
    ax[0].axvline(fc, color=color, lw=0.8, alpha=0.6)
    ax[1].plot([fc, fc], [-180.0, -180.0 + pm], color=color, lw=1.5)
    if text:
        ax[1].annotate(f"PM {pm:.0f} deg @ {fc:.0f} Hz", (fc, -180.0 + pm / 2), xytext=(4, 0), textcoords="offset points",
                       fontsize=7, color=color)  # fmt: skip


def plot_sensitivity(runs: list[LoopMeasurement], designs: list[LoopDesign], path: str | Path | None = None,
                     title: str = "") -> Figure:  # fmt: skip
    """``|S|`` and ``|T|`` (dB) of each run (markers) and design (lines); ``max|S|``
    (the inverse of the stability margin) is the peak of the upper panel."""
    fig, ax = subplots(2, 1, figsize=(9, 7.5), sharex=True)
    for d, style in zip(designs, _DESIGN_STYLE):
        ls, c = style
        ax[0].semilogx(d.f_hz, _db(d.S), ls=ls, color=c, lw=1.2, label=f"design: {d.model}")
        ax[1].semilogx(d.f_hz, _db(d.T), ls=ls, color=c, lw=1.2)
    for r, c in zip(runs, _run_colors(runs)):
        ax[0].semilogx(r.f, _db(r.value("S")), "o", color=c, ms=5, mfc="none", label=f"measured: {r.label}")
        ax[1].semilogx(r.f, _db(r.value("T")), "o", color=c, ms=5, mfc="none")
    for a in ax:
        a.axhline(0.0, color="0.5", lw=0.8)
        a.grid(alpha=0.3, which="both")
    ax[0].set_ylabel("|S| = |U_n/U_exc| (dB)")
    ax[1].set_ylabel("|T| = |U_pi/U_exc| (dB)")
    ax[1].set_xlabel("frequency (Hz)")
    ax[0].set_title(title or "Sensitivity S and complementary sensitivity T")
    ax[0].legend(fontsize=8)
    return finish(fig, path)


__all__ = ["plot_loop", "plot_sensitivity"]

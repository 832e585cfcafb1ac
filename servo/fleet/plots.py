"""Population plots of a fleet table: a histogram per parameter, scatters of the main
pairs, findings per drive.

Each function returns a :class:`matplotlib.figure.Figure` (made without pyplot: nothing
global changes, no backend is chosen); :func:`save` writes one as PNG atomically.
Only the rows whose ``status`` is ok are plotted; outliers (:mod:`servo.fleet.outliers`)
are drawn in red.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from servo.io.plotting import Figure
from matplotlib.ticker import MaxNLocator

from servo.fleet.outliers import MIN_DRIVES, THRESHOLD, robust_z
from servo.io.atomic import atomic_write


def _values(rows: list[dict], c: str) -> np.ndarray:
    return np.array([float(r[c]) if isinstance(r.get(c), (int, float)) and not isinstance(r.get(c), bool) else np.nan
                     for r in rows])  # fmt: skip


def _ok(rows: list[dict]) -> list[dict]:
    return [r for r in rows if r.get("status") == "ok"]


def _grid(n: int, size=(3.2, 2.4)) -> tuple[Figure, list]:
    cols = min(4, max(n, 1))
    nrows = math.ceil(max(n, 1) / cols)
    fig = Figure(figsize=(size[0] * cols, size[1] * nrows), layout="constrained")
    axes = fig.subplots(nrows, cols, squeeze=False).ravel().tolist()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def histograms(rows: list[dict], columns: list[str]) -> Figure:
    """One histogram per column that at least :data:`~servo.fleet.outliers.MIN_DRIVES`
    drives have a value in (a finding's parameters, on a few drives, are listed in the
    report instead), the median dashed, outliers' values as red ticks."""
    good = _ok(rows)
    columns = [c for c in columns if np.isfinite(_values(good, c)).sum() >= MIN_DRIVES]
    fig, axes = _grid(len(columns))
    for ax, c in zip(axes, columns):
        x = _values(good, c)
        x = x[np.isfinite(x)]
        ax.set_title(c, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.hist(x, bins=min(40, max(5, int(math.sqrt(x.size)) + 1)), color="0.6")
        z, med, _ = robust_z(x)
        if math.isfinite(med):
            ax.axvline(med, color="k", ls="--", lw=0.8)
        out = x[np.abs(np.nan_to_num(z)) > THRESHOLD]
        if out.size:
            ax.plot(out, np.zeros(out.size), "|", color="r", ms=12, mew=1.5)
    fig.suptitle(f"fleet: {len(good)} drives (median dashed, robust outliers red)", fontsize=9)
    return fig


def scatters(rows: list[dict], pairs: list[tuple[str, str]]) -> Figure:
    """One scatter per pair ``(x column, y column)``."""
    good = _ok(rows)
    fig, axes = _grid(len(pairs), (3.4, 3.0))
    for ax, (a, b) in zip(axes, pairs):
        x, y = _values(good, a), _values(good, b)
        ax.plot(x, y, ".", ms=4, color="C0")
        ax.set_xlabel(a, fontsize=8)
        ax.set_ylabel(b, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.xaxis.set_major_locator(MaxNLocator(4))
    fig.suptitle(f"fleet: {len(good)} drives, main pairs", fontsize=9)
    return fig


def findings(rows: list[dict]) -> Figure:
    """Diagnosis: the number of findings of each drive (bars coloured by the first
    physics named) and how many drives each physics was found in."""
    good = _ok(rows)
    fig = Figure(figsize=(10, 3.6), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2, width_ratios=(3, 1))
    names = [(r.get("findings") or "").split(",") if r.get("findings") else [] for r in good]
    kinds = sorted({p for n in names for p in n})
    color = {k: f"C{i % 10}" for i, k in enumerate(kinds)}
    ax1.bar(np.arange(len(good)), [len(n) for n in names], color=[color[n[0]] if n else "0.7" for n in names], width=1.0)
    ax1.set_xlabel("drive (table order)", fontsize=8)
    ax1.set_ylabel("findings", fontsize=8)
    ax1.tick_params(labelsize=7)
    ax1.yaxis.set_major_locator(MaxNLocator(integer=True))
    counts = [sum(k in n for n in names) for k in kinds]
    ax2.barh(np.arange(len(kinds)), counts, color=[color[k] for k in kinds])
    ax2.set_yticks(np.arange(len(kinds)), kinds, fontsize=7)
    ax2.set_xlabel("drives", fontsize=8)
    ax2.tick_params(labelsize=7)
    ax2.xaxis.set_major_locator(MaxNLocator(integer=True))
    flagged = sum(bool(n) for n in names)
    fig.suptitle(f"fleet diagnosis: {flagged} of {len(good)} drives with findings", fontsize=9)
    return fig


def save(fig: Figure, path: str | Path, dpi: int = 100) -> Path:
    """Write ``fig`` as PNG at ``path``, atomically."""
    path = Path(path)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"))
    return path


__all__ = ["findings", "histograms", "save", "scatters"]

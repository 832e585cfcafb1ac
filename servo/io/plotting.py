"""Figures without global state, and atomic PNG writing.

Every plot function of the package builds a :class:`matplotlib.figure.Figure` directly
(not through ``pyplot``), returns it, and writes it only when given a path.  So importing
the package or calling a plot function never selects a backend, never registers a figure
with ``pyplot`` (no figure piles up in a long session, none is shown twice in a
notebook) and works headless; a notebook displays the returned figure as the cell's
value (:class:`Figure` has ``_repr_png_``, so a fresh Jupyter kernel draws it too), ``fig.savefig(...)`` writes it anywhere.  Only the command line selects the Agg
backend (:func:`servo.cli.main`).
"""
from __future__ import annotations

from pathlib import Path

import io

from matplotlib import colormaps
from matplotlib import figure as _mpl_figure

from servo.io.atomic import atomic_write


class Figure(_mpl_figure.Figure):
    """A :class:`matplotlib.figure.Figure` that shows itself in a notebook: Jupyter
    calls :meth:`_repr_png_` on the value of a cell, so the figure is drawn even in a
    fresh kernel where ``pyplot`` (and with it the inline backend) was never imported."""

    def _repr_png_(self) -> bytes:
        buf = io.BytesIO()
        self.savefig(buf, format="png", dpi=100, bbox_inches="tight")
        return buf.getvalue()


def subplots(nrows: int = 1, ncols: int = 1, *, figsize=None, **kw):
    """``(Figure, axes)`` like ``pyplot.subplots`` but without ``pyplot``: the figure
    belongs to no backend and to no global registry.  ``kw`` goes to
    :meth:`Figure.subplots` (``sharex``, ``squeeze``, ...)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kw)


def figure(figsize=None) -> Figure:
    """An empty :class:`Figure` outside ``pyplot`` (add axes with ``fig.add_subplot``)."""
    return Figure(figsize=figsize)


def colors(name: str, values):
    """RGBA colours of the colormap ``name`` at ``values`` in [0, 1] (shape ``(n, 4)``)."""
    return colormaps[name](values)


def save_figure(fig: Figure, path: str | Path, dpi: int = 110, tight: bool = True) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically (never half a file); returns the path.
    ``tight``: cropped to what is drawn (``bbox_inches="tight"``, which draws the figure
    twice); False for a figure whose margins are fixed (``subplots_adjust``): drawn once,
    a third less work."""
    path = Path(path)
    bbox = "tight" if tight else None
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png", bbox_inches=bbox))
    return path


def finish(fig: Figure, path: str | Path | None = None, dpi: int = 110, tight: bool = True) -> Figure:
    """The end of every plot function: write ``fig`` to ``path`` when one is given
    (:func:`save_figure`), and return the figure either way."""
    if path is not None:
        save_figure(fig, path, dpi, tight)
    return fig


__all__ = ["Figure", "colors", "figure", "finish", "save_figure", "subplots"]

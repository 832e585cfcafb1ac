"""The figure of a run's PES (:class:`~servo.hdd.pes.PesFigures`), ``pes_<label>.png``.

It builds a Figure without ``pyplot`` (:mod:`servo.io.plotting`), writes it only
when given a path, and returns it.
"""
from __future__ import annotations

import numpy as np

from servo.hdd.pes import PesFigures
from servo.io.plotting import finish, subplots


def pes_plot(fig_data: PesFigures, unit: str = "track", title: str = "", path=None):
    """Four panels: RRO per sector with the NRRO 3 sigma band, the PES spectrum (ASD) with
    its cumulative 3 sigma, and the histogram."""
    p = fig_data
    fig, ax = subplots(2, 2, figsize=(11, 7))
    k = np.arange(p.rro.shape[0])
    a = ax[0, 0]
    a.step(k, p.rro, where="post", color="C3", label=f"RRO (p-p {p.rro_pp:.3g} {unit})")
    a.step(k, p.rro + 3 * p.nrro_sigma, where="post", color="C4", lw=0.8, label=f"RRO +- 3 sigma NRRO ({p.nrro_3sigma:.3g})")
    a.step(k, p.rro - 3 * p.nrro_sigma, where="post", color="C4", lw=0.8)
    a.set(xlabel="sector", ylabel=f"PES ({unit})", title=f"{p.revolutions} revolutions")
    a.legend(fontsize=8)
    a.grid(True, alpha=0.3)
    a = ax[0, 1]
    f = p.f[1:]
    a.loglog(f, np.sqrt(p.psd[1:]), color="C0", lw=0.8)
    a.set(xlabel="frequency (Hz)", ylabel=f"ASD ({unit}/sqrt(Hz))", title="PES spectrum")
    a.grid(True, which="both", alpha=0.3)
    b = a.twinx()
    b.semilogx(f, p.cum_3sigma[1:], color="C1")
    b.set_ylabel(f"cumulative 3 sigma ({unit})", color="C1")
    a = ax[1, 0]
    centres = 0.5 * (p.edges[1:] + p.edges[:-1])
    a.bar(centres, p.counts, width=np.diff(p.edges), color="C2")
    a.set(xlabel=f"PES ({unit})", ylabel="samples", title=f"histogram (3 sigma {p.sigma3:.3g}; outside {sum(p.outside)})")
    a = ax[1, 1]
    a.plot(k, 3 * p.nrro_sigma, color="C4")
    a.set(xlabel="sector", ylabel=f"NRRO 3 sigma ({unit})", title="NRRO per sector")
    a.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return finish(fig, path)

"""The figure of a benchmark evaluation over its perturbed plants (``evaluation.png``)."""
from __future__ import annotations

import numpy as np

from servo.io.plotting import finish, subplots


def evaluation_plot(named: dict, path=None):
    """RRO p-p and NRRO 3 sigma (% of a track) per perturbed plant for each design
    (``{name: studies.hdd.evaluate.evaluate(...)}``)."""
    fig, ax = subplots(2, 1, figsize=(11, 6), sharex=True)
    for i, (name, ev) in enumerate(named.items()):
        rows = [r.row() for r in ev["plants"]]
        x = np.arange(len(rows))
        for a, key in zip(ax, ("rro_pp", "nrro_3sigma")):
            y = [100 * r.get(key, np.nan) for r in rows]
            a.plot(x, y, "o-", ms=3, color=f"C{i}", label=name)
    ax[0].set_ylabel("RRO p-p (% track)")
    ax[1].set_ylabel("NRRO 3 sigma (% track)")
    ax[1].set_xlabel("perturbed plant (benchmark order, K 0, +10, -10 %)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.tight_layout()
    return finish(fig, path)

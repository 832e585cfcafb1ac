"""The figure of a measured frequency response: magnitude with its random-error band,
phase, and coherence."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from servo.io.frequency_response import FrequencyResponse
from servo.io.plotting import finish, subplots


def plot_frf(resp: FrequencyResponse, path: Path | None = None, title: str = "", reference: FrequencyResponse | None = None,
             coherence_min: float = 0.9) -> Figure:  # fmt: skip
    """Bode magnitude (dB re 1 ``resp.unit``) with a +-2 standard-deviation band of the
    random error, phase (deg, wrapped into (-360, 0]), and coherence with the ``coherence_min`` line; points
    below it are drawn faint.  ``reference``: another response drawn dashed (e.g. a
    model).  Written to ``path`` when given."""
    fig, ax = subplots(3, 1, figsize=(9, 9), sharex=True, gridspec_kw={"height_ratios": [3, 2, 1.3]})
    f, mag, c = resp.f_hz, resp.mag_db, resp.coherence
    ph = -np.mod(-np.angle(resp.H, deg=True), 360.0)  # wrapped into (-360, 0]: unwrapping noise runs away
    good = ~(c < coherence_min)  # NaN coherence (unknown) counts as good
    s = np.where(np.isfinite(resp.rel_std), resp.rel_std, 0.0)
    lo = 20 * np.log10(np.maximum(1 - 2 * s, 1e-3))
    hi = 20 * np.log10(1 + 2 * s)
    ax[0].fill_between(f, mag + lo, mag + hi, color="tab:blue", alpha=0.2, lw=0, label="+-2 std (random error)")
    ax[0].semilogx(f, np.where(good, mag, np.nan), color="tab:blue", lw=1.2, label="estimate")
    ax[0].semilogx(f, np.where(good, np.nan, mag), color="tab:blue", lw=0.8, alpha=0.35,
                   label=f"coherence < {coherence_min:g}")  # fmt: skip
    ax[1].semilogx(f, np.where(good, ph, np.nan), color="tab:blue", lw=1.2)
    ax[1].semilogx(f, np.where(good, np.nan, ph), color="tab:blue", lw=0.8, alpha=0.35)
    if reference is not None:
        ax[0].semilogx(reference.f_hz, reference.mag_db, "k--", lw=0.9, label="reference")
        ax[1].semilogx(reference.f_hz, reference.phase_deg, "k--", lw=0.9)
    ax[2].semilogx(f, c, color="k", lw=0.9, label="of the estimate (input's share of the output)")
    for key, col in (("coherence_ru", "tab:orange"), ("coherence_ry", "tab:green")):
        if key in resp.meta:
            ax[2].semilogx(f, resp.meta[key], color=col, lw=0.7, label=key.replace("coherence_", "instrument, "))
    ax[2].axhline(coherence_min, color="r", lw=0.8, ls=":")
    ax[2].set_ylim(0, 1.05)
    ax[0].set_ylabel(f"|H| (dB re 1 {resp.unit})" if resp.unit else "|H| (dB)")
    ax[1].set_ylabel("phase (deg, in (-360, 0])")
    ax[2].set_ylabel("coherence")
    ax[2].set_xlabel("frequency (Hz)")
    m = resp.meta
    ax[0].set_title(title or f"{m.get('method', 'frequency response')}: {m.get('segments', '?')} segments of "
                    f"{m.get('nperseg', '?')} samples, {m.get('resolution_hz', float('nan')):.3g} Hz apart")  # fmt: skip
    ax[0].legend(fontsize=8, loc="lower left")
    ax[2].legend(fontsize=8, loc="lower left")
    for a in ax:
        a.grid(alpha=0.3, which="both")
    return finish(fig, path)


__all__ = ["plot_frf"]

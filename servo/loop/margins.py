"""Gain and phase margins and crossover of a loop's frequency response.

:func:`margins` hands the loop ``L`` (complex, at frequencies in Hz) to
:func:`control.stability_margins` as a :class:`control.FrequencyResponseData` and
returns plain numbers in Hz and dB; crossings are found only inside the given band.

A measured loop has a few points per octave.  python-control interpolates an FRD with
a spline of the complex values in linear frequency, which between sparse points beside
a resonance overshoots by tens of percent (a measured loop without the compensator, a
lightly damped 90 Hz pivot mode next to the crossover, put the crossover 20 Hz off).
So :func:`resample` first interpolates the points the way a Bode plot reads them:
``log|L|`` and the unwrapped phase, each linear in ``log f``, onto a dense grid; that
is what goes to python-control.  A design is evaluated on a dense grid directly.
"""
from __future__ import annotations

import math
import warnings

import numpy as np


def _hz(w) -> list[float]:
    return [float(v) / (2 * math.pi) for v in np.atleast_1d(w)]


def _db(g) -> list[float | None]:
    out = []
    for v in np.atleast_1d(g):
        v = float(v)
        out.append(20 * math.log10(v) if math.isfinite(v) and v > 0 else None)
    return out


def resample(f_hz, L, n: int = 1200) -> tuple[np.ndarray, np.ndarray]:
    """``(f, L)`` on ``n`` log-spaced points over ``[f_hz[0], f_hz[-1]]``: ``log|L|`` and the
    unwrapped phase of the points, each interpolated linearly in ``log f``."""
    f = np.asarray(f_hz, dtype=float)
    L = np.asarray(L, dtype=complex)
    g = np.geomspace(f[0], f[-1], n)
    lf, lg = np.log(f), np.log(g)
    mag = np.interp(lg, lf, np.log(np.abs(L)))
    ph = np.interp(lg, lf, np.unwrap(np.angle(L)))
    return g, np.exp(mag + 1j * ph)


def margins(f_hz, L, dense: bool = False) -> dict:
    """Margins of the loop ``L`` (complex (n,)) at ``f_hz`` (Hz, (n,), increasing, n >= 4).

    ``dense``: the points are dense already (a design on a fine grid); else they are
    first :func:`resample`\\ d.

    Returns ``crossover_hz`` (the gain crossover of the smallest phase margin, None if
    ``|L|`` does not cross 1 in the band), ``phase_margin_deg``, ``gain_margin_db`` and
    ``phase_crossover_hz`` (the -180 deg crossing whose gain margin is closest to 0 dB;
    negative dB: the loop gain may *drop* that much, a conditionally stable loop),
    ``stability_margin`` (least ``|1 + L|`` in the band, i.e. ``1/max|S|``) and its
    frequency, and every crossing: ``all_crossovers_hz``/``all_phase_margins_deg``,
    ``all_phase_crossovers_hz``/``all_gain_margins_db``; ``band_hz`` the band searched.
    """
    import control

    f = np.asarray(f_hz, dtype=float)
    L = np.asarray(L, dtype=complex)
    ok = np.isfinite(L) & np.isfinite(f)
    f, L = f[ok], L[ok]
    if f.size < 4:
        raise ValueError("margins need at least 4 finite points")
    band = [float(f[0]), float(f[-1])]
    if not dense:
        f, L = resample(f, L)
    frd = control.FrequencyResponseData(L, 2 * np.pi * f)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gm, pm, _, w180, wc, _ = control.stability_margins(frd, returnall=True)
    gm, pm = np.atleast_1d(gm), np.atleast_1d(pm)
    w180, wc = np.atleast_1d(w180), np.atleast_1d(wc)
    out: dict = {
        "band_hz": band,
        "all_crossovers_hz": _hz(wc),
        "all_phase_margins_deg": [float(v) for v in pm],
        "all_phase_crossovers_hz": _hz(w180),
        "all_gain_margins_db": _db(gm),
    }
    if wc.size:
        i = int(np.argmin(np.abs(pm)))  # the smallest phase margin, as python-control reports it
        out["crossover_hz"], out["phase_margin_deg"] = _hz(wc[i])[0], float(pm[i])
    else:
        out["crossover_hz"] = out["phase_margin_deg"] = None
    fin = np.isfinite(gm) & (gm > 0)
    if fin.any():
        i = int(np.flatnonzero(fin)[np.argmin(np.abs(np.log(gm[fin])))])
        out["gain_margin_db"], out["phase_crossover_hz"] = _db(gm[i])[0], _hz(w180[i])[0]
    else:
        out["gain_margin_db"] = out["phase_crossover_hz"] = None
    d = np.abs(1.0 + L)  # on the dense grid (python-control reports local minima only)
    j = int(np.argmin(d))
    out["stability_margin"], out["stability_margin_hz"] = float(d[j]), float(f[j])
    return out


__all__ = ["margins", "resample"]

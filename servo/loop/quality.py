"""How well a measured loop's margins are known: their uncertainty from the measurement's
own random error, and a warning when one exceeds its tolerance.

Each measured point of ``L`` carries the standard deviation of its random error relative
to ``|L|`` (``rel_std``, :class:`servo.io.frequency_response.FrequencyResponse`).  Read at
a margin's frequency (interpolated linearly in ``log f``), ``e`` gives to first order

* the crossover: ``f_c * e / |d ln|L| / d ln f|`` (Hz);
* a phase margin: ``e`` rad (the phase error of a complex error of relative size ``e``);
* a gain margin: ``20/ln(10) * e`` dB;
* max|S|: ``20/ln(10) * |T| * e`` dB (``dS/S = -T dL/L``).

A margin whose uncertainty (one standard deviation) exceeds :data:`TOLERANCE` gets a
warning line: the excitation was too small against the noise (raise ``--levels``) or
the loop was not in its small-signal regime.
"""
from __future__ import annotations

import math

import numpy as np

#: Tolerances (one standard deviation): crossover (relative), phase margin (deg), gain
#: margin and max|S| (dB).
TOLERANCE = {"crossover_hz": 0.02, "phase_margin_deg": 2.0, "gain_margin_db": 0.5, "max_S_db": 0.5}

DB = 20.0 / math.log(10.0)


def _at(f: np.ndarray, y: np.ndarray, x: float) -> float:
    return float(np.interp(math.log(x), np.log(f), y))


def uncertainty(m: dict, f_hz, L, rel_std) -> dict:
    """One-standard-deviation uncertainty of the margins ``m`` (:func:`servo.design.margins.margins`
    of the measured ``L`` at ``f_hz``, each point's ``rel_std``): the keys of
    :data:`TOLERANCE` (``crossover_hz`` in Hz), None where the margin is None or the
    error unknown."""
    f = np.asarray(f_hz, float)
    L = np.asarray(L, complex)
    e = np.asarray(rel_std, float)
    ok = np.isfinite(e) & np.isfinite(L) & (f > 0)
    out = dict.fromkeys(TOLERANCE)
    if ok.sum() < 2:
        return out
    f, L, e = f[ok], L[ok], e[ok]
    if m.get("crossover_hz"):
        fc = m["crossover_hz"]
        slope = np.gradient(np.log(np.abs(L)), np.log(f))
        s = abs(_at(f, slope, fc))
        out["crossover_hz"] = fc * _at(f, e, fc) / s if s > 0 else math.inf
        out["phase_margin_deg"] = math.degrees(_at(f, e, fc))
    if m.get("gain_margin_hz"):
        out["gain_margin_db"] = DB * _at(f, e, m["gain_margin_hz"])
    if m.get("max_S_hz"):
        T = np.abs(L / (1.0 + L))
        out["max_S_db"] = DB * _at(f, T, m["max_S_hz"]) * _at(f, e, m["max_S_hz"])
    return out


def warnings_for(label: str, m: dict, u: dict) -> list[str]:
    """One line per margin of ``m`` whose uncertainty ``u`` exceeds :data:`TOLERANCE`."""
    out = []
    for k, tol in TOLERANCE.items():
        v = u.get(k)
        if v is None or m.get(k) is None:
            continue
        rel = v / m[k] if k == "crossover_hz" else v
        if not rel <= tol:
            unit = {"crossover_hz": " Hz", "phase_margin_deg": " deg"}.get(k, " dB")
            limit = f"{100 * tol:g} %" if k == "crossover_hz" else f"{tol:g}{unit}"
            out.append(f"{label}: {k} = {m[k]:.4g}{unit} +- {v:.3g}{unit}, beyond its tolerance ({limit}): the "
                       "excitation is too small against the noise (raise --levels)")  # fmt: skip
    return out


__all__ = ["TOLERANCE", "uncertainty", "warnings_for"]

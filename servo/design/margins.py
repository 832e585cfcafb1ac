"""The margins of a feedback loop, as an engineer reads them: one rule for every caller
(a design, ``servo loop``'s designs and measurements, the HDD benchmark's evaluation).

The loop ``L`` is broken at one point of a negative-feedback loop (``e = r - y``, the
closed loop ``L/(1 + L)``); ``S = 1/(1 + L)``, ``T = L/(1 + L)``.  From ``L`` over the
whole band (a design: from far below the crossover up to the Nyquist frequency):

* **stability** first.  An unstable closed loop has no margins: :func:`margins` reports
  ``stable = False`` (with the closed-loop pole radius when the loop is known as a
  system, else the number of unstable closed-loop poles the Nyquist criterion counts,
  :func:`nyquist_unstable`) and every margin None.
* **crossover** ``crossover_hz``: the *lowest* frequency where ``|L|`` crosses 1 (the
  servo bandwidth); ``phase_margin_deg`` there.  A lightly damped mode poking above
  0 dB adds crossovers (``crossovers_hz``, ``phase_margins_deg``); a phase-stabilised
  one may show a negative value there and still be stable.
* **gain margins**: at every phase crossover (``Im L = 0``, ``Re L < 0``, the Nyquist
  frequency included when ``L`` is real and negative there) the factor ``1/|L|`` by
  which the loop gain may change before the closed loop reaches instability:
  ``side = "upper"`` (> 0 dB: the gain may *grow* that much) or ``"lower"`` (< 0 dB: it
  may *drop* that much; a conditionally stable loop, e.g. an integrator on a double
  integrator).  The *binding* margin, the smallest in size, is ``gain_margin_db`` (with
  ``gain_margin_hz``, ``gain_margin_side``); ``gain_margin_upper_db`` and
  ``gain_margin_lower_db`` the nearest on each side (None when there is none: the gain
  may change without limit on that side).
* **delay margin** ``delay_margin_s``: the smallest extra loop delay that makes the loop
  unstable, ``min_i (PM_i mod 360 deg) / (360 deg * f_i)`` over the gain crossovers.
* **peaks** ``max_S_db`` / ``max_S_hz``, ``max_T_db`` / ``max_T_hz`` over the band;
  ``stability_margin = 1/max|S|`` (the least distance of ``L`` from -1).

Frequencies in Hz.  ``tests/test_margins.py`` cross-checks every number against
``control.stability_margins`` for every controller kind.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.optimize import brentq, minimize_scalar

#: The margins reported for a loop (None when there are none, e.g. for an unstable loop).
MARGIN_KEYS = ("crossover_hz", "phase_margin_deg", "phase_margin_min_deg", "gain_margin_db", "gain_margin_hz",
               "gain_margin_side", "gain_margin_upper_db", "gain_margin_lower_db", "delay_margin_s",
               "max_S_db", "max_S_hz", "max_T_db", "max_T_hz", "stability_margin", "stability_margin_hz")  # fmt: skip


def resample(f_hz, L, n: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """``(f, L)`` on ``n`` log-spaced points over ``[f_hz[0], f_hz[-1]]``: ``log|L|`` and the
    unwrapped phase of the points, each interpolated linearly in ``log f`` (how a Bode plot
    reads sparse points; a spline of the complex values overshoots beside a resonance)."""
    f = np.asarray(f_hz, dtype=float)
    L = np.asarray(L, dtype=complex)
    g = np.geomspace(f[0], f[-1], n)
    lf, lg = np.log(f), np.log(g)
    mag = np.interp(lg, lf, np.log(np.abs(L)))
    ph = np.interp(lg, lf, np.unwrap(np.angle(L)))
    return g, np.exp(mag + 1j * ph)


def nyquist_unstable(f_hz, L, nyquist_hz: float) -> int | None:
    """Closed-loop poles outside the unit circle, by the Nyquist criterion, of a sampled
    loop ``L`` given on a dense grid ``f_hz`` from far below its crossover up to
    ``nyquist_hz`` (the last point).  Assumes no open-loop pole outside the unit circle;
    open-loop poles at ``z = 1`` (integrators, ``m`` of them, read from the low-frequency
    slope of ``|L|``) are indented around from outside.  With ``Delta`` the unwrapped
    phase change of ``1 + L`` from the lowest frequency to Nyquist, the contour (unit
    circle clockwise, conjugate halves, the indentation adding ``m*pi``) winds
    ``(m*pi - 2*Delta) / (2*pi)`` times around 0: that many unstable closed-loop poles.
    None when the grid does not reach Nyquist or ``|L|`` is not above 10 at its low end."""
    f = np.asarray(f_hz, dtype=float)
    L = np.asarray(L, dtype=complex)
    if f.size < 8 or abs(f[-1] / nyquist_hz - 1.0) > 1e-6:
        return None
    slope = -np.log(abs(L[1]) / abs(L[0])) / np.log(f[1] / f[0])
    m = int(round(slope)) if slope > 0.5 else 0
    if m and abs(L[0]) < 10.0:
        return None
    ph = np.unwrap(np.angle(1.0 + L))
    w = (m * math.pi - 2.0 * (ph[-1] - ph[0])) / (2.0 * math.pi)
    return int(round(w))


def _crossings(f, v, response, fun, mask=None) -> list[float]:
    """Frequencies where ``fun(L)`` changes sign between grid points (``mask``: only the
    intervals where it is True), refined on ``response`` (exact) or by linear
    interpolation of ``fun(L)`` in ``log f``."""
    s = fun(v)
    idx = np.nonzero(np.sign(s[:-1]) * np.sign(s[1:]) < 0)[0]
    out = []
    for i in idx:
        if mask is not None and not mask[i]:
            continue
        if response is not None:
            out.append(brentq(lambda x: fun(response(np.array([x])))[0], f[i], f[i + 1], xtol=1e-10 * f[i]))
        else:
            t = s[i] / (s[i] - s[i + 1])
            out.append(float(np.exp(np.log(f[i]) + t * (np.log(f[i + 1]) - np.log(f[i])))))
    return out


def _at(f, v, response, x: list[float]) -> np.ndarray:
    """``L`` at the frequencies ``x``: exact, or interpolated (log|L|, unwrapped phase in log f)."""
    if not x:
        return np.zeros(0, complex)
    if response is not None:
        return np.asarray(response(np.array(x)), complex)
    lx, lf = np.log(x), np.log(f)
    return np.exp(np.interp(lx, lf, np.log(np.abs(v))) + 1j * np.interp(lx, lf, np.unwrap(np.angle(v))))


def _peak(f, g, response, fun) -> tuple[float, float]:
    """``(max, frequency)`` of ``fun(L)`` (real) over the grid, refined on ``response``."""
    i = int(np.argmax(g))
    if response is None or g.size < 3:
        return float(g[i]), float(f[i])
    lo, hi = f[max(i - 1, 0)], f[min(i + 1, f.size - 1)]
    r = minimize_scalar(lambda x: -fun(response(np.array([x])))[0], bounds=(lo, hi), method="bounded",
                        options={"xatol": 1e-9 * f[i]})  # fmt: skip
    return (float(-r.fun), float(r.x)) if -r.fun > g[i] else (float(g[i]), float(f[i]))


def _db(x: float) -> float:
    return 20.0 * math.log10(x)


def margins(f_hz, L, *, dense: bool = False, response: Callable | None = None, nyquist_hz: float | None = None,
            stable: bool | None = None, pole_radius: float | None = None) -> dict:  # fmt: skip
    """Margins of the loop ``L`` (complex (n,)) at ``f_hz`` (Hz, (n,), increasing, n >= 4);
    the rule is the module doc's.

    ``dense``: the points are dense already (a design on a fine grid); else (a
    measurement) they are first :func:`resample`\\ d.  ``response``: ``f (Hz) -> L``,
    the exact loop, to refine every crossing and peak on.  ``nyquist_hz``: the loop's
    Nyquist frequency; when the points reach it and ``stable`` is not given, stability
    is judged by :func:`nyquist_unstable`.  ``stable`` / ``pole_radius``: the closed
    loop's, when known as a system.

    Returns the keys of :data:`MARGIN_KEYS` (None for an unstable loop), ``stable``
    (True, False or None: unknown), ``pole_radius``, ``unstable_poles``, the lists
    ``crossovers_hz``, ``phase_margins_deg``, ``phase_crossovers_hz``, ``gain_margins``
    (``{"hz", "db", "side", "binding"}`` each) and
    ``band_hz`` the band searched."""
    f = np.asarray(f_hz, dtype=float)
    v = np.asarray(L, dtype=complex)
    ok = np.isfinite(v) & np.isfinite(f) & (f > 0)
    f, v = f[ok], v[ok]
    if f.size < 4:
        raise ValueError("margins need at least 4 finite points")
    out: dict = {"band_hz": [float(f[0]), float(f[-1])], "stable": stable, "pole_radius": pole_radius,
                 "unstable_poles": None}  # fmt: skip
    if not dense:
        f, v = resample(f, v)
    if stable is None and nyquist_hz is not None:
        n_out = nyquist_unstable(f, v, nyquist_hz)
        if n_out is not None:
            out["stable"], out["unstable_poles"] = n_out == 0, n_out
    empty = dict.fromkeys(MARGIN_KEYS)
    empty.update(crossovers_hz=[], phase_margins_deg=[], phase_crossovers_hz=[], gain_margins=[])  # fmt: skip
    out.update(empty)
    if out["stable"] is False:
        return out

    # gain crossovers, phase margins, delay margin
    wg = _crossings(f, v, response, lambda x: np.log(np.abs(x)))
    pm = np.degrees(np.angle(_at(f, v, response, wg))) % 360.0 - 180.0
    out["crossovers_hz"], out["phase_margins_deg"] = [float(w) for w in wg], [float(p) for p in pm]
    if wg:
        out["crossover_hz"], out["phase_margin_deg"] = float(wg[0]), float(pm[0])
        out["phase_margin_min_deg"] = float(pm.min())
        out["delay_margin_s"] = float(min((p % 360.0) / (360.0 * w) for p, w in zip(pm, wg)))

    # phase crossovers and gain margins (the Nyquist point included: L is real there)
    wp = _crossings(f, v, response, lambda x: x.imag, mask=(v.real[:-1] < 0) & (v.real[1:] < 0))
    hp = _at(f, v, response, wp)
    at_nyquist = any(abs(w / nyquist_hz - 1.0) <= 1e-6 for w in wp) if nyquist_hz else False
    if nyquist_hz is not None and abs(f[-1] / nyquist_hz - 1.0) <= 1e-6 and not at_nyquist:
        h_nyq = complex(_at(f, v, response, [float(nyquist_hz)])[0]) if response is not None else complex(v[-1])
        if h_nyq.real < 0 and abs(h_nyq.imag) <= 1e-6 * abs(h_nyq):
            wp, hp = wp + [float(nyquist_hz)], np.append(hp, h_nyq)
    gms = [{"hz": float(w), "db": -_db(abs(h)), "side": "upper" if abs(h) < 1 else "lower", "binding": False}
           for w, h in zip(wp, hp) if abs(h) > 0]  # fmt: skip
    out["phase_crossovers_hz"] = [g["hz"] for g in gms]
    up = [g for g in gms if g["side"] == "upper"]
    lo = [g for g in gms if g["side"] == "lower"]
    out["gain_margin_upper_db"] = min(g["db"] for g in up) if up else None
    out["gain_margin_lower_db"] = max(g["db"] for g in lo) if lo else None
    if gms:
        b = min(gms, key=lambda g: abs(g["db"]))
        b["binding"] = True
        out["gain_margin_db"], out["gain_margin_hz"], out["gain_margin_side"] = b["db"], b["hz"], b["side"]
    out["gain_margins"] = gms

    # sensitivity peaks
    s_fun = lambda x: 1.0 / np.abs(1.0 + x)  # noqa: E731
    t_fun = lambda x: np.abs(x / (1.0 + x))  # noqa: E731
    s_max, s_hz = _peak(f, s_fun(v), response, s_fun)
    t_max, t_hz = _peak(f, t_fun(v), response, t_fun)
    out.update(max_S_db=_db(s_max), max_S_hz=s_hz, max_T_db=_db(t_max), max_T_hz=t_hz,
               stability_margin=1.0 / s_max, stability_margin_hz=s_hz)  # fmt: skip
    return out


__all__ = ["MARGIN_KEYS", "margins", "nyquist_unstable", "resample"]

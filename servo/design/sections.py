"""Second-order sections: stability check and frequency response of a cascade.

A cascade is a float64 array (n, 6) of rows ``b0 b1 b2 a0 a1 a2`` (scipy's ``sos``
layout, ``a0 = 1``), run in order.  :func:`check` is the contract of every cascade a
:class:`~servo.design.design.Design` holds: at most :data:`MAX_SECTIONS` sections, finite
coefficients, every pole strictly inside the unit circle except (when allowed) one
integrator pole at ``z = 1``.
"""
from __future__ import annotations

import numpy as np

#: Most sections one cascade may hold (what the compiled biquad kernel is sized for).
MAX_SECTIONS = 8

#: How close to ``z = 1`` a pole counts as the integrator's (a designed integrator lands
#: there exactly; rounding leaves it within ~1e-15).
INTEGRATOR_TOL = 1e-9


def section_poles(row: np.ndarray) -> np.ndarray:
    """Poles (complex, 0 to 2 of them) of one section ``b0 b1 b2 a0 a1 a2``."""
    a = np.trim_zeros(np.asarray(row[3:], dtype=float), "b")
    return np.roots(a) if a.shape[0] > 1 else np.zeros(0, complex)


def check(sos, name: str = "cascade", integrators: int = 0) -> np.ndarray:
    """``sos`` as a C-contiguous float64 (n, 6) array, normalised to ``a0 = 1``, after
    checking it: ``n <= MAX_SECTIONS``, finite, every pole ``|p| < 1`` except at most
    ``integrators`` poles at ``z = 1``.  Raises ValueError naming the offending section."""
    s = np.array(sos, dtype=np.float64, copy=True).reshape(-1, 6) if np.size(sos) else np.zeros((0, 6))
    if s.shape[0] > MAX_SECTIONS:
        raise ValueError(f"{name}: {s.shape[0]} sections, more than {MAX_SECTIONS}")
    if not np.all(np.isfinite(s)):
        raise ValueError(f"{name}: coefficients are not finite")
    used = 0
    for i, row in enumerate(s):
        if row[3] == 0.0:
            raise ValueError(f"{name}: section {i} has a0 = 0")
        s[i] /= row[3]
        for p in section_poles(s[i]):
            if abs(p - 1.0) < INTEGRATOR_TOL and used < integrators:
                used += 1
                continue
            if not abs(p) < 1.0:
                raise ValueError(f"{name}: section {i} has a pole at z = {p:.6g} (|z| = {abs(p):.6g}), "
                                 "not strictly inside the unit circle")  # fmt: skip
    return np.ascontiguousarray(s)


def response(sos: np.ndarray, f_hz, fs: float) -> np.ndarray:
    """Frequency response of the cascade at ``f_hz`` (Hz, any shape) for sample rate
    ``fs`` (Hz): ``prod_i (b_i(z) / a_i(z))`` at ``z = exp(j*2*pi*f/fs)``."""
    f = np.asarray(f_hz, dtype=float)
    zi = np.exp(-2j * np.pi * f / fs)  # z^-1
    h = np.ones(f.shape, dtype=complex)
    for b0, b1, b2, a0, a1, a2 in np.asarray(sos).reshape(-1, 6):
        h *= (b0 + b1 * zi + b2 * zi * zi) / (a0 + a1 * zi + a2 * zi * zi)
    return h


def poles(sos: np.ndarray) -> np.ndarray:
    """All poles of the cascade (complex)."""
    rows = np.asarray(sos).reshape(-1, 6)
    return np.concatenate([section_poles(r) for r in rows]) if rows.shape[0] else np.zeros(0, complex)

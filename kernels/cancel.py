"""Cancellation terms beyond the paper's eq. (9): what ``servo diagnose`` can find and a
static term can cancel (issue 14).  Each is the negative of a force of the drive's model
(``kernels/plant.py``), written the same way, so that with exact estimates the plant seen
by ``u_n`` stays ``J*x'' = u_n`` (eq. 10).

* :func:`viscous_asymmetry`: ``B*a*s*v``, the part of ``B*(1 + s*a)*v`` beyond eq. (9)'s
  ``B*v`` (A);
* :func:`coulomb_stribeck`: ``s*(Fc' + (Fs' - Fc')*exp(-(v/vs)^2))`` with ``Fc' = Fc*(1 + s*a)``,
  ``Fs' = Fs*(1 + s*a)``: a Coulomb friction beyond the pivot's Dahl element, with its
  Stribeck rise and direction asymmetry (A);
* :func:`periodic`: ``sum_i A_i*sin(2*pi*i*x/period + phi_i)``, a force periodic in
  position (cogging, a screw's lead), harmonics ``i = 1..n`` (A), evaluated as sine and
  cosine coefficients (:func:`harmonic_coefficients`) with one ``sin``/``cos`` pair;
* :func:`force_constant`: ``kf(x) = 1 + k1*(x/stroke) + k2*(x/stroke)^2``; the command is
  divided by it (a gain, not a force);
* :func:`cubic_spring`: ``k3*x^3``, a hardening (``k3 > 0``) or softening spring (A);
* :func:`dead_zone_inverse`: ``u + sgn(u)*w``, the command whose input dead zone of
  half-width ``w`` gives ``u`` (an input transform, not a force).
"""
import math

import numpy as np
from numba import float64, int64
from numba.core.types import NestedArray

from kernels._cache import kernel

#: Harmonics of the periodic term a record holds.
MAX_HARMONICS = 4
harmonics_t = NestedArray(float64, (MAX_HARMONICS,))


@kernel(float64(float64, float64, float64, float64), helper=True)
def viscous_asymmetry(v, s, B, a):
    """``B*a*s*v`` (A): ``v`` m/s, ``s`` direction, ``B`` A*s/m, ``a`` asymmetry."""
    return B * a * s * v


@kernel(float64(float64, float64, float64, float64, float64, float64), helper=True)
def coulomb_stribeck(v, s, Fc, Fs, vs, a):
    """``s*(Fc' + (Fs' - Fc')*exp(-(v/vs)^2))`` (A): ``Fc``, ``Fs`` A, ``vs`` m/s."""
    fc = Fc * (1.0 + s * a)
    fs = Fs * (1.0 + s * a)
    return s * (fc + (fs - fc) * math.exp(-((v / vs) ** 2)))


@kernel(float64(float64, harmonics_t, harmonics_t, int64, float64), inline="always", helper=True)
def periodic(x, a, b, n, period):
    """``sum_{i<n} a[i]*sin((i+1)*th) + b[i]*cos((i+1)*th)`` (A), ``th = 2*pi*x/period``
    (``x``, ``period`` m): the force ``sum_i A_i*sin((i+1)*th + phi_i)`` with ``a_i =
    A_i*cos(phi_i)``, ``b_i = A_i*sin(phi_i)`` (A; :func:`harmonic_coefficients`).

    One ``sin`` and one ``cos`` per sample whatever ``n``: the harmonics come from the
    fundamental by the angle-addition recurrence ``sin((k+1)th) = sin(k*th)*cos(th) +
    cos(k*th)*sin(th)`` (and its cosine), a few roundings per harmonic for what a ``sin``
    per harmonic costs (~15 ns each): within ~2e-14 of ``sum |A_i|`` of the direct sum of
    sines over the first ten periods from ``x = 0``; further out both forms lose digits
    alike, as the rounding of ``2*pi*x/period`` grows with it.
    """
    if n <= 0:
        return 0.0
    th = 2.0 * math.pi * x / period
    s1 = math.sin(th)
    c1 = math.cos(th)
    sk = s1
    ck = c1
    f = a[0] * sk + b[0] * ck
    for i in range(1, n):
        sk, ck = sk * c1 + ck * s1, ck * c1 - sk * s1
        f += a[i] * sk + b[i] * ck
    return f


def harmonic_coefficients(amplitudes, phases):
    """``(a, b)`` of :func:`periodic` from amplitudes ``A_i`` (A) and phases ``phi_i``
    (rad), each shape ``(n,)``, ``n <= MAX_HARMONICS``: ``a = A*cos(phi)``, ``b = A*sin(phi)``."""
    amp, ph = np.asarray(amplitudes, dtype=float), np.asarray(phases, dtype=float)
    return amp * np.cos(ph), amp * np.sin(ph)


@kernel(float64(float64, float64, float64, float64), helper=True)
def force_constant(x, k1, k2, stroke):
    """``kf(x)`` (dimensionless), as :func:`kernels.plant.force_constant`."""
    r = x / stroke
    return 1.0 + k1 * r + k2 * r * r


@kernel(float64(float64, float64), helper=True)
def cubic_spring(x, k3):
    """``k3*x^3`` (A): ``x`` m, ``k3`` A/m^3, as the drive's (:func:`kernels.plant.drive_force`)."""
    return k3 * x * x * x


@kernel(float64(float64, float64), helper=True)
def dead_zone_inverse(u, w):
    """``u + sgn(u)*w`` (A; ``u`` at 0): the command an input dead zone of half-width ``w``
    (A) turns into ``u`` (:func:`kernels.plant.dead_zone`)."""
    if u > 0.0:
        return u + w
    if u < 0.0:
        return u - w
    return 0.0

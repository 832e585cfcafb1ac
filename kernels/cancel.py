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
  position (cogging, a screw's lead), harmonics ``i = 1..n`` (A);
* :func:`force_constant`: ``kf(x) = 1 + k1*(x/stroke) + k2*(x/stroke)^2``; the command is
  divided by it (a gain, not a force).
"""
import math

from numba import float64, int64
from numba.core.types import NestedArray

from kernels._cache import kernel

#: Harmonics of the periodic term a record holds.
MAX_HARMONICS = 4
harmonics_t = NestedArray(float64, (MAX_HARMONICS,))


@kernel(float64(float64, float64, float64, float64))
def viscous_asymmetry(v, s, B, a):
    """``B*a*s*v`` (A): ``v`` m/s, ``s`` direction, ``B`` A*s/m, ``a`` asymmetry."""
    return B * a * s * v


@kernel(float64(float64, float64, float64, float64, float64, float64))
def coulomb_stribeck(v, s, Fc, Fs, vs, a):
    """``s*(Fc' + (Fs' - Fc')*exp(-(v/vs)^2))`` (A): ``Fc``, ``Fs`` A, ``vs`` m/s."""
    fc = Fc * (1.0 + s * a)
    fs = Fs * (1.0 + s * a)
    return s * (fc + (fs - fc) * math.exp(-((v / vs) ** 2)))


@kernel(float64(float64, harmonics_t, harmonics_t, int64, float64))
def periodic(x, amp, phase, n, period):
    """``sum_{i<n} amp[i]*sin(2*pi*(i+1)*x/period + phase[i])`` (A); ``x``, ``period`` m."""
    f = 0.0
    for i in range(n):
        f += amp[i] * math.sin(2.0 * math.pi * (i + 1) * x / period + phase[i])
    return f


@kernel(float64(float64, float64, float64, float64))
def force_constant(x, k1, k2, stroke):
    """``kf(x)`` (dimensionless), as :func:`kernels.plant.force_constant`."""
    r = x / stroke
    return 1.0 + k1 * r + k2 * r * r

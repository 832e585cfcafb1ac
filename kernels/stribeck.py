"""A Stribeck rise held by bristles (the LuGre friction model's element) along a recorded motion.

The element's force is ``dFs*w`` with the normalised bristle state ``w`` in ``[-1, 1]``:
along a position increment ``dx`` it relaxes towards its steady state ``phi(v)*sgn(dx)``
(``phi`` the Stribeck curve's fall with speed) over the distance ``length*phi(v)``,

    w <- w_ss + (w - w_ss)*exp(-abs(dx)/(length*phi)),    w_ss = phi*sgn(dx),

the exact solution of LuGre's ``dz/dx = 1 - sgn(dx)*sigma0*z/g(v)`` over ``dx`` at a
held speed (``length = dFs/sigma0`` the bristles' deflection at rest).  A vanishing
``length`` is the memoryless Stribeck column ``phi(v)*sgn(v)``; a Stribeck velocity far
above every speed is a Dahl element (exponent 1).
"""
import math

from numba import float64, void

from kernels._cache import kernel


@kernel(void(float64[::1], float64[::1], float64, float64, float64, float64[::1]))
def stribeck_bristle_trace(x, v, vs, delta, length, out):
    """The normalised bristle state ``out[k]`` (-) along positions ``x`` (m) with
    velocities ``v`` (m/s), from rest (``w = 0``): Stribeck velocity ``vs`` (m/s), shape
    exponent ``delta`` of ``phi = exp(-abs(v/vs)^delta)``, deflection at rest ``length`` (m)."""
    w = 0.0
    out[0] = 0.0
    for k in range(1, x.shape[0]):
        dx = x[k] - x[k - 1]
        if dx != 0.0:
            phi = max(math.exp(-(abs(v[k] / vs) ** delta)), 1e-12)
            w_ss = math.copysign(phi, dx)
            w = w_ss + (w - w_ss) * math.exp(-abs(dx) / (length * phi))
        out[k] = w

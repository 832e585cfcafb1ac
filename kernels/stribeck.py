"""A Stribeck rise held by bristles (the LuGre friction model's element) along a recorded motion.

The element's force is ``dFs*w`` with the normalised bristle state ``w`` in ``[-1, 1]``:
along a position increment ``dx`` it relaxes towards its steady state ``phi(v)*sgn(dx)``
(``phi`` the Stribeck curve's fall with speed) over the distance ``length*phi(v)``,

    w <- w_ss + (w - w_ss)*exp(-abs(dx)/(length*phi)),    w_ss = phi*sgn(dx),

the exact solution of LuGre's ``dz/dx = 1 - sgn(dx)*sigma0*z/g(v)`` over ``dx`` at a
held speed (``length = dFs/sigma0`` the bristles' deflection at rest).  A vanishing
``length`` is the memoryless Stribeck column ``phi(v)*sgn(v)``; a Stribeck velocity far
above every speed is a Dahl element (exponent 1).

The curve ``phi`` does not depend on the state: it is computed a block of samples at a
time by numpy's vectorised ``log`` and ``exp`` (``|v/vs|^delta`` as
``exp(delta*log|v/vs|)``, the square for the Gaussian shape), and only the recursion
runs sample by sample in the compiled loop.  A scalar ``pow`` per sample made the trace
twice as slow (31 ms against 13-15 ms for 1e6 samples, 2026-11-28); the two agree to
a few units of the last place (a relative 2e-15 of the state).
"""
import math

import numpy as np
from numba import float64

from kernels._cache import kernel

#: samples a block: the curve's two work arrays stay in the cache (2 x 256 kB)
BLOCK = 1 << 15


@kernel(float64(float64[::1], float64[::1], float64, float64, float64[::1]))
def bristle_relax(dx, phi, length, w, out):
    """The recursion of the module doc over one block: position increments ``dx`` (m),
    the curve ``phi`` (-) at each, the state ``w`` before the block; writes the state
    after each increment into ``out`` and returns the last."""
    for k in range(dx.shape[0]):
        d = dx[k]
        if d != 0.0:
            p = phi[k]
            w_ss = math.copysign(p, d)
            w = w_ss + (w - w_ss) * math.exp(-abs(d) / (length * p))
        out[k] = w
    return w


def stribeck_bristle_trace(x, v, vs, delta, length, out):
    """The normalised bristle state ``out[k]`` (-) along positions ``x`` (m) with
    velocities ``v`` (m/s), from rest (``w = 0``): Stribeck velocity ``vs`` (m/s), shape
    exponent ``delta`` of ``phi = max(exp(-abs(v/vs)^delta), 1e-12)``, deflection at rest
    ``length`` (m).  ``x``, ``v``, ``out``: float64 arrays of one length, (n,)."""
    n = x.shape[0]
    if n == 0:
        return
    out[0] = 0.0
    w = 0.0
    m = min(BLOCK, max(n - 1, 1))
    dx, phi = np.empty(m), np.empty(m)
    vs, delta, length = float(vs), float(delta), float(length)
    with np.errstate(divide="ignore"):  # log(0) at rest: -inf, phi = 1 there, as 0**delta gives
        for a in range(1, n, BLOCK):
            e = min(a + BLOCK, n)
            d, p = dx[: e - a], phi[: e - a]
            np.subtract(x[a:e], x[a - 1 : e - 1], out=d)
            np.divide(v[a:e], vs, out=p)
            np.abs(p, out=p)
            if delta == 2.0:
                np.multiply(p, p, out=p)
            else:
                np.log(p, out=p)
                np.multiply(p, delta, out=p)
                np.exp(p, out=p)
            np.negative(p, out=p)
            np.exp(p, out=p)
            np.maximum(p, 1e-12, out=p)
            w = bristle_relax(d, p, length, w, out[a:e])

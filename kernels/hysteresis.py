"""The Dahl estimate (eq. 6-7) along a whole recorded motion, for fitting its parameters.

Runs exactly the per-sample estimator of the controller (:func:`kernels.dahl.dahl_update`
with the deadbanded direction of :func:`kernels.compensator.direction`) over arrays, so a
fitted model is the model the compensator will run.
"""
from numba import float64, void

from kernels._cache import kernel
from kernels.compensator import direction
from kernels.dahl import dahl_update


@kernel(void(float64[::1], float64[::1], float64, float64, float64, float64, float64, float64[::1]))
def dahl_trace(x, v, deadband, sigma, Ha, alpha, H0, out):
    """Dahl estimate ``out[k]`` (A) along positions ``x`` (m) with velocities ``v`` (m/s).

    The direction is ``sgn(v)`` with a ``deadband`` (m/s); the estimator starts at
    ``x[0]`` moving in + with its latest turnaround there at ``H0`` (A), as the controller
    does.  ``sigma`` (A/m), ``Ha`` (A), ``alpha``: eq. (6)."""
    s = 1.0
    x_r = x[0]
    H_r = H0
    x_ext = x[0]
    for k in range(x.shape[0]):
        s_new = direction(s, v[k], deadband)
        s, x_r, H_r, x_ext, H = dahl_update(x[k], s_new, s, x_r, H_r, x_ext, sigma, Ha, alpha)
        out[k] = H

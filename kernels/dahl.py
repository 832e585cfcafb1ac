"""Simplified Dahl hysteresis (Gong et al. 2002, eq. 6-7).

Dahl's model in the position domain, with ``s = sgn(x')``::

    dH/dx = sigma * (1 - s*H/Ha)**alpha                      (6)

``sigma`` (A/m) is the slope at a turnaround (pre-sliding stiffness), ``Ha`` (A) the
asymptote (the sliding friction level), ``alpha`` (>0) the shape exponent.  The model is
rate independent: ``H`` depends on the path of ``x`` only.  Writing ``y = 1 - s*H/Ha``
(0 at the asymptote, 2 at the opposite one) and ``xi = s*(x - x_r)`` for the distance
travelled since the latest turnaround ``(x_r, H_r)``, eq. (6) integrates in closed form::

    alpha == 1:  y = y_r * exp(-sigma*xi/Ha)                                   (7)
    alpha != 1:  y = max(0, y_r**(1-alpha) + (alpha-1)*sigma*xi/Ha)**(1/(1-alpha))

and ``H = s*Ha*(1 - y)``, saturated at ``+-Ha``.  Only the latest turnaround is memorized.

All functions here take and return float64 scalars (tuples for the estimator) so they
inline into the per-sample kernels without allocation.
"""
import math

from numba import float64
from numba.types import UniTuple

from kernels._cache import kernel


@kernel(float64(float64, float64, float64, float64, float64), helper=True)
def dahl_slope(H, s, sigma, Ha, alpha):
    """Right-hand side of eq. (6): dH/dx (A/m) at force ``H`` (A) moving in direction ``s``."""
    y = 1.0 - s * H / Ha
    if y <= 0.0:
        return 0.0
    return sigma * y**alpha


@kernel(float64(float64, float64, float64, float64, float64, float64), helper=True)
def dahl_flow(H, dx, s, sigma, Ha, alpha):
    """Exact integral of eq. (6) from force ``H`` over a displacement ``dx`` (m).

    The direction ``s`` (+1/-1) is held fixed, so ``dx`` against ``s`` walks back along
    the same branch (the flow of an autonomous ODE is a group: this is what makes the
    incremental form and the closed form from the turnaround agree).  Returns the new
    force in A, within ``[-Ha, Ha]``.
    """
    y0 = 1.0 - s * H / Ha
    if y0 < 0.0:
        y0 = 0.0
    elif y0 > 2.0:
        y0 = 2.0
    xi = s * dx
    if alpha == 1.0:
        y = y0 * math.exp(-sigma * xi / Ha)
    else:
        e = 1.0 - alpha
        if y0 == 0.0:
            if e < 0.0:
                y = 0.0  # alpha > 1 at the asymptote: a fixed point of the (Lipschitz) flow
            else:
                z = -e * sigma * xi / Ha  # y**(1-alpha) from y0 = 0
                y = z ** (1.0 / e) if z > 0.0 else 0.0
        else:
            # y**(1-alpha) = y0**(1-alpha) * (1 - w), linear in xi; written as
            # y = y0*exp(log1p(-w)/e), which stays exact as alpha -> 1 (it tends to the
            # exponential) where z**(1/e) would cancel catastrophically
            w = e * sigma * xi / (Ha * y0**e)
            if w >= 1.0:
                # alpha < 1: the asymptote is reached in finite distance;
                # alpha > 1: y -> infinity walking back, i.e. the opposite saturation
                y = 0.0 if e > 0.0 else 2.0
            else:
                y = y0 * math.exp(math.log1p(-w) / e)
    if y > 2.0:
        y = 2.0
    return s * Ha * (1.0 - y)


@kernel(float64(float64, float64, float64, float64, float64, float64, float64), helper=True)
def dahl_closed(x, x_r, H_r, s, sigma, Ha, alpha):
    """Closed form of eq. (7): ``H(x)`` from the latest turnaround ``(x_r, H_r)``."""
    return dahl_flow(H_r, x - x_r, s, sigma, Ha, alpha)


@kernel(
    UniTuple(float64, 5)(
        float64, float64, float64, float64, float64, float64, float64, float64, float64
    ),
    helper=True,
)
def dahl_update(x, s_new, s, x_r, H_r, x_ext, sigma, Ha, alpha):
    """One sample of the Dahl hysteresis estimate ``H_hat`` (eq. 6-7).

    Arguments: measured position ``x`` (m); the direction of motion this sample
    ``s_new`` (+1/-1, from a velocity with a deadband); the estimator state: direction
    ``s``, latest turnaround ``(x_r, H_r)``, and ``x_ext``, the furthest position reached
    in direction ``s`` since that turnaround; Dahl parameters.

    When the direction changes, the turnaround is placed at the extreme ``x_ext`` (not
    where the reversal was *detected*: a deadband detects it late) and ``H_r`` becomes the
    estimate there; this is the only memory (paper: "only the latest turnaround value is
    memorized").  Returns ``(s, x_r, H_r, x_ext, H_hat)``; ``H_hat`` is saturated at
    ``+-Ha`` by construction.
    """
    if s_new != s:
        H_r = dahl_flow(H_r, x_ext - x_r, s, sigma, Ha, alpha)
        x_r = x_ext
        s = s_new
        x_ext = x
    if s * (x - x_ext) > 0.0:
        x_ext = x
    H = dahl_flow(H_r, x - x_r, s, sigma, Ha, alpha)
    return s, x_r, H_r, x_ext, H

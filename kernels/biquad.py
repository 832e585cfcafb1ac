"""Cascades of second-order sections (biquads), transposed direct form II.

A section ``(b0, b1, b2, a0, a1, a2)`` with ``a0 = 1`` (scipy.signal's ``sos`` rows)::

    y    = b0*x + z1
    z1' = b1*x - a1*y + z2
    z2' = b2*x - a2*y

The coefficients and states live in a controller's records as fixed-size nested arrays
(:data:`MAX_SECTIONS` rows) so that a tick allocates nothing; ``n`` sections are used.
"""
from numba import float64, int64, void
from numba.core.types import NestedArray

from kernels._cache import kernel

#: Rows of a cascade in a record.
MAX_SECTIONS = 8
sos_t = NestedArray(float64, (MAX_SECTIONS, 6))
zi_t = NestedArray(float64, (MAX_SECTIONS, 2))


@kernel(float64(sos_t, zi_t, int64, float64), helper=True)
def sos_cascade(sos, z, n, x):
    """One sample ``x`` through sections ``0..n-1`` of ``sos``, updating their states ``z``;
    returns the output (the unit of ``x`` times the cascade's gain)."""
    for i in range(n):
        y = sos[i, 0] * x + z[i, 0]
        z[i, 0] = sos[i, 1] * x - sos[i, 4] * y + z[i, 1]
        z[i, 1] = sos[i, 2] * x - sos[i, 5] * y
        x = y
    return x


@kernel(float64(sos_t, zi_t, zi_t, int64, float64), helper=True)
def sos_cascade_try(sos, z, z_new, n, x):
    """:func:`sos_cascade` that leaves ``z`` as it is and writes the updated states into
    ``z_new`` (commit them with :func:`sos_commit`): for anti-windup."""
    for i in range(n):
        y = sos[i, 0] * x + z[i, 0]
        z_new[i, 0] = sos[i, 1] * x - sos[i, 4] * y + z[i, 1]
        z_new[i, 1] = sos[i, 2] * x - sos[i, 5] * y
        x = y
    return x


@kernel(void(zi_t, zi_t, int64), helper=True)
def sos_commit(z, z_new, n):
    """Copy the states of sections ``0..n-1`` from ``z_new`` into ``z``."""
    for i in range(n):
        z[i, 0] = z_new[i, 0]
        z[i, 1] = z_new[i, 1]

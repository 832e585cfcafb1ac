"""Screening statistics of a diagnosis's large grids, without the grid's columns.

A diagnosis scans thousands of variants of a term (a mode's frequency and damping, a
cogging period) by how much of the current model's residual each explains
(:func:`servo.diagnose.select.screen_stats`): per cross-validation fold ``b`` and variant
``j``, the correlation ``a[b, j] = C_bj r_b`` of the variant's columns with the residual
and their Gram ``H[b, j] = C_bj W_b C_bj'`` over the fold's usable rows.  Built in numpy,
each chunk of variants is first written out as a (J, k, m) array of columns and read
back: at 100 000 rows and 3 000 cogging periods, 4.8 GB of memory traffic per round.
These kernels compute the columns one row (or one tile of rows) at a time and
accumulate the sums at once, with the same column arithmetic:

* :func:`cogging_stats`: ``sin``/``cos`` of ``2*pi*x*k_j`` for a uniform grid of
  wavenumbers ``k_j = k0 + j*dk``, by complex rotation (one multiplication per variant
  and row, as the numpy path did);
* :func:`biquad_stats`: the rows ``y`` through each variant's biquad ``b_j/a_j``, in the
  transposed direct form II with scipy's ``lfilter`` order of operations (the same
  filtered columns, to the bit), all variants advanced together sample by sample.

Row sums are accumulated in row order (numpy's matrix products sum in another order:
the statistics agree to rounding).  Units are those of the columns and the residual.
"""
import math

import numpy as np
from numba import float64, int64, void

from kernels._cache import kernel

#: rows per tile of :func:`cogging_stats` (its rotating columns stay in the L1 cache)
TILE = 256


@kernel(void(float64[::1], float64[::1], float64[::1], int64[::1], int64[::1], float64, float64,
             float64[:, :, ::1], float64[:, :, :, ::1]), fastmath=True)  # fmt: skip
def cogging_stats(x, r, w, starts, stops, k0, dk, a, H):
    """Screening sums of ``[sin(2*pi*x*k_j), cos(2*pi*x*k_j)]`` for ``k_j = k0 + j*dk``.

    ``x`` (m,) positions of the rows (m), ``r`` (m,) residual (zero on unusable rows),
    ``w`` (m,) row weights (1 usable, 0 not), ``starts``/``stops`` (K,) each fold's row
    range, ``k0``, ``dk`` (1/m).  Writes ``a`` (K, J, 2) and ``H`` (K, J, 2, 2).

    ``fastmath``: the sums over a tile's rows are reassociated (vectorised); each
    column is ``exp(2*pi*i*x*k0)`` rotated ``j`` times by ``exp(2*pi*i*x*dk)``."""
    K = starts.shape[0]
    J = a.shape[1]
    zr = np.empty(TILE)
    zi = np.empty(TILE)
    sr = np.empty(TILE)
    si = np.empty(TILE)
    a[:] = 0.0
    H[:] = 0.0
    for b in range(K):
        for t0 in range(starts[b], stops[b], TILE):
            t1 = min(t0 + TILE, stops[b])
            T = t1 - t0
            for i in range(T):
                p = 2.0 * math.pi * x[t0 + i]
                zr[i] = math.cos(p * k0)
                zi[i] = math.sin(p * k0)
                sr[i] = math.cos(p * dk)
                si[i] = math.sin(p * dk)
            for j in range(J):
                if j > 0:
                    for i in range(T):
                        re = zr[i] * sr[i] - zi[i] * si[i]
                        zi[i] = zr[i] * si[i] + zi[i] * sr[i]
                        zr[i] = re
                a0 = 0.0
                a1 = 0.0
                h00 = 0.0
                h01 = 0.0
                h11 = 0.0
                for i in range(T):
                    s = zi[i]
                    c = zr[i]
                    ri = r[t0 + i]
                    wi = w[t0 + i]
                    a0 += s * ri
                    a1 += c * ri
                    h00 += wi * s * s
                    h01 += wi * s * c
                    h11 += wi * c * c
                a[b, j, 0] += a0
                a[b, j, 1] += a1
                H[b, j, 0, 0] += h00
                H[b, j, 0, 1] += h01
                H[b, j, 1, 1] += h11
        for j in range(J):
            H[b, j, 1, 0] = H[b, j, 0, 1]


@kernel(void(float64[::1], float64[::1], float64[::1], int64[::1], int64[::1], float64[:, ::1], float64[:, ::1],
             float64, float64[:, :, ::1], float64[:, :, :, ::1]))  # fmt: skip
def biquad_stats(y, r, w, starts, stops, B, A, sign, a, H):
    """Screening sums of ``sign * lfilter(B[:, j], A[:, j], y)`` for each variant ``j``.

    ``y`` (m,) the signal filtered (the rows of the force), ``r``, ``w``, ``starts``,
    ``stops`` as in :func:`cogging_stats` (the folds must be in row order and not
    overlap); ``B``, ``A`` (3, J): column ``j`` is variant ``j``'s biquad, with
    ``A[0, j] = 1`` (coefficient-major, so the loop over the variants vectorises); the filter
    runs over all rows from zero state.  Writes ``a`` (K, J, 1) and ``H`` (K, J, 1, 1).
    The filter's arithmetic is scipy's ``lfilter`` (transposed direct form II) operation
    for operation, so the columns are those of the numpy path to the bit."""
    m = y.shape[0]
    K = starts.shape[0]
    J = B.shape[1]
    z1 = np.zeros(J)
    z2 = np.zeros(J)
    a[:] = 0.0
    H[:] = 0.0
    b = 0
    for i in range(m):
        xi = y[i]
        while b < K and i >= stops[b]:
            b += 1
        if b < K and i >= starts[b]:
            ri = r[i]
            wi = w[i]
            for j in range(J):
                yj = z1[j] + B[0, j] * xi
                z1[j] = z2[j] + xi * B[1, j] - yj * A[1, j]
                z2[j] = xi * B[2, j] - yj * A[2, j]
                c = sign * yj
                a[b, j, 0] += c * ri
                H[b, j, 0, 0] += wi * c * c
        else:
            for j in range(J):
                yj = z1[j] + B[0, j] * xi
                z1[j] = z2[j] + xi * B[1, j] - yj * A[1, j]
                z2[j] = xi * B[2, j] - yj * A[2, j]

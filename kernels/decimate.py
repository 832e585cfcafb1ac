"""Zero-phase filtering and decimation of one column in one pass over its samples.

A diagnosis passes every full-rate column (the regressor's, each candidate's, the
force) through a zero-phase Chebyshev filter and keeps every ``q``-th sample
(:func:`servo.diagnose.signals.decimate`).  ``scipy.signal.sosfiltfilt`` does that
with five full-length arrays per column (the odd extension, the forward pass's copy and
output, the reversed copy and the backward pass's output) before the slice keeps a
tenth of them: at 1e6 samples ~23 ms a column, of which the recursion itself is ~7 ms.
:func:`filtfilt_decimate` writes the extension and the forward pass into one buffer and
runs the backward pass over it keeping only the decimated outputs.

The arithmetic is scipy's to the bit: the odd extension ``2*x[0] - x[edge:0:-1]`` (and
its mirror at the end), the sections in the transposed direct form II in the order of
operations of scipy's ``_sosfilt`` (no fused multiply-add: Numba does not contract
without ``fastmath``), the initial states ``zi * x_ext[0]`` forward and ``zi * y[-1]``
backward (``zi`` from ``scipy.signal.sosfilt_zi``).  Units are those of the column.
"""
import numpy as np
from numba import float64, int64, void

from kernels._cache import kernel


@kernel(void(float64[:, ::1], float64[:, ::1], float64[::1], int64, int64, float64[::1], float64[::1]))
def filtfilt_decimate(sos, zi, x, edge, q, y, out):
    """``out[:] = scipy.signal.sosfiltfilt(sos, x, padlen=edge)[(n-1) % q::q]`` for ``x`` (n,).

    ``sos`` (s, 6) second-order sections with ``a0 = 1``; ``zi`` (s, 2) their steady
    states for a unit step (``scipy.signal.sosfilt_zi``); ``edge`` the odd extension's
    length at each end (``0 < edge < n``); ``q`` >= 1 the decimation factor; ``y``
    (n + 2*edge,) scratch, overwritten; ``out`` (ceil(n/q),) the kept samples of the
    zero-phase filtered ``x``.  The caller allocates both (numpy backs a large array with
    huge pages where the system allows: at 1e7 samples a buffer allocated here took
    20 000 page faults)."""
    n = x.shape[0]
    ns = sos.shape[0]
    N = n + 2 * edge
    for i in range(edge):
        y[i] = 2.0 * x[0] - x[edge - i]
    for i in range(n):
        y[edge + i] = x[i]
    for i in range(edge):
        y[edge + n + i] = 2.0 * x[n - 1] - x[n - 2 - i]
    z = np.empty((ns, 2))
    x0 = y[0]
    for s in range(ns):
        z[s, 0] = zi[s, 0] * x0
        z[s, 1] = zi[s, 1] * x0
    for k in range(N):
        cur = y[k]
        for s in range(ns):
            new = sos[s, 0] * cur + z[s, 0]
            z[s, 0] = sos[s, 1] * cur - sos[s, 4] * new + z[s, 1]
            z[s, 1] = sos[s, 2] * cur - sos[s, 5] * new
            cur = new
        y[k] = cur
    y0 = y[N - 1]
    for s in range(ns):
        z[s, 0] = zi[s, 0] * y0
        z[s, 1] = zi[s, 1] * y0
    start = (n - 1) % q
    m = (n - 1 - start) // q + 1
    j = m - 1
    nxt = edge + start + j * q  # the buffer index of the next kept sample, walking back
    for k in range(N - 1, edge - 1, -1):
        cur = y[k]
        for s in range(ns):
            new = sos[s, 0] * cur + z[s, 0]
            z[s, 0] = sos[s, 1] * cur - sos[s, 4] * new + z[s, 1]
            z[s, 1] = sos[s, 2] * cur - sos[s, 5] * new
            cur = new
        if k == nxt:
            out[j] = cur
            j -= 1
            nxt -= q
            if j < 0:
                break

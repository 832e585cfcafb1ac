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


@kernel(void(float64[:, ::1], float64[:, ::1], float64[::1], int64, int64, int64, int64, float64[::1]))
def _four_sections(sos, zi, y, N, edge, n, q, out):
    """The two passes of :func:`filtfilt_decimate` over its extended buffer ``y`` (N,)
    for a filter of exactly four sections, the same operations in the same order with
    the eight states in local variables rather than an array: the loop-carried states
    stay in registers (a 1e6-sample column: 10.8 ms instead of 13.8 ms of CPU, load 4)."""
    b00, b01, b02, a01, a02 = sos[0, 0], sos[0, 1], sos[0, 2], sos[0, 4], sos[0, 5]
    b10, b11, b12, a11, a12 = sos[1, 0], sos[1, 1], sos[1, 2], sos[1, 4], sos[1, 5]
    b20, b21, b22, a21, a22 = sos[2, 0], sos[2, 1], sos[2, 2], sos[2, 4], sos[2, 5]
    b30, b31, b32, a31, a32 = sos[3, 0], sos[3, 1], sos[3, 2], sos[3, 4], sos[3, 5]
    x0 = y[0]
    p0, q0 = zi[0, 0] * x0, zi[0, 1] * x0
    p1, q1 = zi[1, 0] * x0, zi[1, 1] * x0
    p2, q2 = zi[2, 0] * x0, zi[2, 1] * x0
    p3, q3 = zi[3, 0] * x0, zi[3, 1] * x0
    for k in range(N):
        cur = y[k]
        new = b00 * cur + p0
        p0 = b01 * cur - a01 * new + q0
        q0 = b02 * cur - a02 * new
        cur = new
        new = b10 * cur + p1
        p1 = b11 * cur - a11 * new + q1
        q1 = b12 * cur - a12 * new
        cur = new
        new = b20 * cur + p2
        p2 = b21 * cur - a21 * new + q2
        q2 = b22 * cur - a22 * new
        cur = new
        new = b30 * cur + p3
        p3 = b31 * cur - a31 * new + q3
        q3 = b32 * cur - a32 * new
        y[k] = new
    y0 = y[N - 1]
    p0, q0 = zi[0, 0] * y0, zi[0, 1] * y0
    p1, q1 = zi[1, 0] * y0, zi[1, 1] * y0
    p2, q2 = zi[2, 0] * y0, zi[2, 1] * y0
    p3, q3 = zi[3, 0] * y0, zi[3, 1] * y0
    start = (n - 1) % q
    j = (n - 1 - start) // q
    nxt = edge + start + j * q  # the buffer index of the next kept sample, walking back
    for k in range(N - 1, edge - 1, -1):
        cur = y[k]
        new = b00 * cur + p0
        p0 = b01 * cur - a01 * new + q0
        q0 = b02 * cur - a02 * new
        cur = new
        new = b10 * cur + p1
        p1 = b11 * cur - a11 * new + q1
        q1 = b12 * cur - a12 * new
        cur = new
        new = b20 * cur + p2
        p2 = b21 * cur - a21 * new + q2
        q2 = b22 * cur - a22 * new
        cur = new
        new = b30 * cur + p3
        p3 = b31 * cur - a31 * new + q3
        q3 = b32 * cur - a32 * new
        if k == nxt:
            out[j] = new
            j -= 1
            nxt -= q
            if j < 0:
                break


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
    if ns == 4:  # the rows' eighth-order filter: its states held in registers
        _four_sections(sos, zi, y, N, edge, n, q, out)
        return
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

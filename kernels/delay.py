"""Shift register for delayed commands (the plant's input delay, the link's latency)."""
from numba import float64

from kernels._cache import kernel


@kernel(float64(float64[::1], float64))
def shift_in(buf, u):
    """Push ``u`` into ``buf`` (``buf[0]`` newest) and return the value pushed out, i.e. the
    one pushed ``len(buf)`` calls ago.  An empty buffer is no delay: ``u`` comes back."""
    n = buf.shape[0]
    if n == 0:
        return u
    out = buf[n - 1]
    for i in range(n - 1, 0, -1):
        buf[i] = buf[i - 1]
    buf[0] = u
    return out

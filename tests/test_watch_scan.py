"""The watchdog's one-pass scan (kernels/watch.py) against the definition it implements:
the first full window of ``w`` rows holding more than ``most`` at-limit rows, however the
rows are cut into looks."""
import numpy as np
from hypothesis import given, settings, strategies as st

from kernels.watch import first_outside, first_over_share


def brute(u, limit, w, most):
    flags = (np.abs(u) >= limit).astype(int)
    for end in range(w - 1, len(u)):
        s = flags[end - w + 1 : end + 1].sum()
        if s > most:
            return end, s
    return -1, 0


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(0, 300), w=st.integers(1, 40), share=st.floats(0.0, 0.99),
       p=st.floats(0.0, 1.0), cuts=st.lists(st.integers(0, 300), max_size=6))  # fmt: skip
def test_sliding_window_scan_matches_its_definition(seed, n, w, share, p, cuts):
    rng = np.random.default_rng(seed)
    u = np.where(rng.random(n) < p, 1.0, 0.5) * rng.choice([-1.0, 1.0], n)
    rows = np.zeros((n, 3))
    rows[:, 2] = u
    most = share * w
    want = brute(u, 1.0, w, most)
    ring, carry = np.zeros(w, np.uint8), np.zeros(3, np.int64)
    got, start = (-1, 0), 0
    for stop in sorted({min(c, n) for c in cuts} | {n}):
        j, count = first_over_share(np.ascontiguousarray(rows[start:stop]), 2, 1.0, ring, carry, most)
        if j >= 0:
            got = (start + j, count)
            break
        start = stop
    assert got == want


def test_first_outside_counts_nan_as_outside():
    rows = np.zeros((5, 2))
    rows[3, 0] = np.nan
    assert first_outside(rows, 0, 1.0) == 3
    rows[1, 0] = -1.0
    assert first_outside(rows, 0, 1.0) == 1
    assert first_outside(np.zeros((4, 2)), 0, 1.0) == -1

"""The periodic term of the compensator (kernels/cancel.py, issue 14) is evaluated from one
sin/cos pair, its harmonics by angle addition: it must equal the force it cancels,
``sum_i A_i*sin(2*pi*i*x/period + phi_i)`` written term by term with a sin per harmonic,
to rounding, over positions spanning many periods and for every number of harmonics."""
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from kernels.cancel import MAX_HARMONICS, harmonic_coefficients, periodic


def direct(x, amp, phase, period):
    return sum(A * math.sin(2.0 * math.pi * (i + 1) * x / period + ph) for i, (A, ph) in enumerate(zip(amp, phase)))


def padded(values):
    out = np.zeros(MAX_HARMONICS)
    out[: len(values)] = values
    return out


amplitudes = st.lists(st.floats(1e-6, 1e-2), min_size=1, max_size=MAX_HARMONICS)


@settings(max_examples=200, deadline=None)
@given(amp=amplitudes, data=st.data(), x=st.floats(-15e-3, 15e-3), period=st.floats(1e-6, 1e-3))
def test_periodic_equals_a_sin_per_harmonic(amp, data, x, period):
    phase = data.draw(st.lists(st.floats(-2 * math.pi, 2 * math.pi), min_size=len(amp), max_size=len(amp)))
    a, b = harmonic_coefficients(amp, phase)
    got = periodic(x, padded(a), padded(b), len(amp), period)
    want = direct(x, amp, phase, period)
    # the two forms round the argument 2*pi*k*x/period differently (by up to k ULPs of it): beyond
    # a few roundings of the amplitudes, the difference grows with the number of periods from 0
    # (worst seen over 50 000 random draws: half this bound)
    turns = abs(x / period)
    assert abs(got - want) <= sum(amp) * (5e-14 + 8 * MAX_HARMONICS * turns * 2.2e-16), (got, want)


def test_no_harmonics_is_no_force():
    assert periodic(3e-4, np.ones(MAX_HARMONICS), np.ones(MAX_HARMONICS), 0, 1e-4) == 0.0


def test_a_quarter_period_moves_the_fundamental_to_its_cosine():
    a, b = harmonic_coefficients([2e-3], [0.0])
    assert abs(periodic(0.25e-4, padded(a), padded(b), 1, 1e-4) - 2e-3) < 1e-18

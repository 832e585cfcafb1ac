"""Benchmark: a diagnosis grows linearly with the recording.

One recording of the null drive (:func:`servo.diagnose.concealed.concealed_recording`)
is simulated once at :data:`SIZES`'s largest length; the diagnosis runs on its first
1e5, 1e6 and 3e6 samples (prefixes of one recording: the same motion and the same
statistics, only more of them).  A stage that scans the rest of the recording for
every event (what the breakaway test's ``_toward`` did before 2026-11-26: 0.36 s at
1e6 samples, 3.2 s at 3e6) makes the time grow faster than the samples.

What is asserted is an exponent measured in a form a busy neighbour does not break:
each diagnosis's CPU time over that of a reference workload on the same prefix timed
just before and after it (four columns decimated by a zero-phase Chebyshev filter,
linear in the samples), so that a load that comes and goes between sizes cancels (the
diagnosis holds BLAS to one thread, so its process time is one core's work; in wall
time, at load 21-33 on the 2 cores, a diagnosis of minutes against a reference of
seconds read 1.12 with the code before and 1.19 after on 2026-11-28, against 0.95 at
load 12-18; in CPU time 1.11 at load 16-24, where the diagnosis's system time a sample
grew with the length and its user time did not: glibc's fresh pages for every array
above 32 MB, which the command's allocator setting, applied here too, avoids); the
exponent is
``1 +`` the least-squares slope of ``log(seconds/reference)`` against ``log(samples)``.
It must not exceed :data:`EXPONENT_MAX`.  Run with ``python -m pytest
bench/test_diagnose_scaling.py -s``.  It took 3.5 min at load 12-18 on the 2 cores (the
simulation of 3e6 samples, then diagnoses of 3, 38 and 127 s); not yet timed idle.  It
is in the slow tier.

At these lengths it does not catch the quadratic ``_toward`` it was written after: that
stage was ~12 % of the time at 3e6 samples, and the fixed costs at 1e5 pull the fitted
exponent below 1 (0.95 measured); it guards against a stage that grows faster than that.
Nor is the exponent the algorithm's alone: a candidate that passes the selection test
only on the longer prefixes brings its refinement and another round with it (the
number of rounds at each length is recorded and printed beside the times).
"""
import time

import numpy as np
import pytest
from scipy import signal

from servo.diagnose.concealed import Scenario, concealed_recording
from servo.diagnose.job import diagnose
from servo.io.allocator import keep_freed_memory
from servo.io.recording import Recording

SIZES = (100_000, 1_000_000, 3_000_000)
EXPONENT_MAX = 1.2
"""The issue's goal is 1.1 (a diagnosis linear in the samples, within 10 %), which this
recording does not meet, and not for a stage that grows faster than the samples: every
stage's CPU a sample is flat from 1e6 to 3e6.  From 1e6 samples on, two candidates pass
the selection test on this null (a switch of the friction at the reversals, where the
null drive sticks exactly, worth 0.06-0.09 % of the held-out SSE: too little for 1e5
samples to show), so their refinement and a second round run there and not at 1e5
(``rounds`` in the record: 1, 2, 2); the held-out proof then drops the term.  CI's
clean run of 2026-11-28 measured 1.152 (0.71, 9.75, 30.49 s of CPU); with the Stribeck
bristle trace computed a block at a time, 1.119, 1.120 and 1.084 against the code
before's 1.139 in the same hour (load 20-25; 0.76-0.92, 9.10-10.05, 29.1-29.3 s against
0.92, 11.27, 33.22 s).  The bound, 1.2, leaves 0.08 above the worst for a busy neighbour's
spread (the exponent of one code read 1.08 to 1.15 across loads on 2026-11-28;
docs/studies/2026-11-28-diagnose-scaling-round5.md)."""


@pytest.fixture(scope="module")
def recording():
    rec, _ = concealed_recording(None, 0.0, seed=3, scenario=Scenario(duration_s=SIZES[-1] / 50_000))
    assert rec.n == SIZES[-1]
    return rec


def _prefix(rec: Recording, n: int) -> Recording:
    return Recording(rec.t[:n], rec.u[:n], rec.x[:n], None, source=f"{rec.source}[:{n}]")


#: the reference's filter, designed once: ``scipy.signal.decimate`` designs it on every call
#: (25 ms of fixed cost, which made the reference grow 4.3x from 1e5 to 1e6 samples)
REFERENCE_SOS = signal.cheby1(8, 0.05, 0.8 / 10, output="sos")


def _reference_s(rec: Recording) -> float:
    """CPU seconds of four full-rate columns through a zero-phase Chebyshev filter and
    decimated by 10 (the rows' operation, linear in the samples)."""
    t0 = time.process_time()
    for c in (rec.u, rec.x, rec.u, rec.x):
        signal.sosfiltfilt(REFERENCE_SOS, np.asarray(c, float))[::10].copy()
    return time.process_time() - t0


def exponent(samples, seconds, reference) -> float:
    """``1 +`` the least-squares slope of ``log(seconds/reference)`` on ``log(samples)``."""
    return 1.0 + float(np.polyfit(np.log(samples), np.log(np.asarray(seconds) / np.asarray(reference)), 1)[0])


def test_exponent_of_a_linear_and_a_quadratic_cost():
    """The exponent reads 1 for a cost proportional to the samples, 2 for the square."""
    n = np.array(SIZES, float)
    assert exponent(n, 3e-6 * n, 1e-7 * n) == pytest.approx(1.0)
    assert exponent(n, 1e-12 * n**2, 1e-7 * n) == pytest.approx(2.0)


@pytest.mark.slow
def test_diagnosis_is_linear_in_the_samples(recording, record):
    keep_freed_memory()  # as servo diagnose does: large arrays reused, not faulted in afresh
    diagnose(_prefix(recording, 20_000))  # the first call's one-time costs (filter designs, kernels) out of the way
    seconds, reference, rounds = [], [], []
    for n in SIZES:
        rec = _prefix(recording, n)
        before = _reference_s(rec)
        t0 = time.process_time()
        D = diagnose(rec)
        seconds.append(time.process_time() - t0)
        reference.append(0.5 * (before + _reference_s(rec)))
        rounds.append(len(D.rounds))  # the selection's rounds: more work where a candidate passes (module doc)
    k = exponent(SIZES, seconds, reference)
    record.check("diagnose_exponent", exponent=k, exponent_max=EXPONENT_MAX, samples=list(SIZES), seconds=seconds,
                 reference_s=reference, rounds=rounds)  # fmt: skip
    print("\ndiagnose: " + ", ".join(f"{n:.0e} samples {s:.2f} s (reference {r:.3f} s, {q} rounds)"
                                     for n, s, r, q in zip(SIZES, seconds, reference, rounds))
          + f"; exponent {k:.3f} (bound {EXPONENT_MAX:g})")  # fmt: skip
    assert k <= EXPONENT_MAX, f"the diagnosis grows as samples^{k:.2f}"

"""Benchmark: ``servo diagnose`` of a one-million-sample recording in under a minute.

The recording is a concealed-effect recording of the simulated drive (a Dahl pivot of
0.2 mA with a 3 um Dahl length under the long-stroke scenario), 20 s at 50 kHz.  The
benchmark times the whole diagnosis (rows, baseline, every candidate of the vocabulary
over blocked cross-validation until none pays, quantisation test, the proof on the
held-out part with short-horizon simulations, locate tests), not the plots or the files.
Run with ``python -m pytest bench/test_diagnose.py``.
"""
import numpy as np
import pytest

from servo.diagnose.concealed import Scenario, concealed_recording
from servo.diagnose.run import diagnose

BUDGET_S = 60.0
SAMPLES = 1_000_000


@pytest.fixture(scope="module")
def million():
    rec, truth = concealed_recording("hysteresis", 2e-4, seed=1, scenario=Scenario(duration_s=SAMPLES / 50_000))
    assert rec.n == SAMPLES
    return rec


def test_diagnose_one_million_samples_under_a_minute(benchmark, million, record):
    D = benchmark.pedantic(diagnose, args=(million,), rounds=1, iterations=1)
    seconds = benchmark.stats.stats.max
    record.check("diagnose_1M_samples", seconds=seconds, budget_s=BUDGET_S, samples=SAMPLES,
                 findings=[f.physics for f in D.findings])  # fmt: skip
    print(f"\ndiagnose: {SAMPLES} samples in {seconds:.1f} s (budget {BUDGET_S:.0f} s); findings "
          f"{[f.physics for f in D.findings]}")  # fmt: skip
    assert seconds < BUDGET_S
    assert [f.physics for f in D.findings] == ["hysteresis"]
    assert np.isfinite(D.errors["test_output_nrmse"]["after"])

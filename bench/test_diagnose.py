"""Benchmark: ``servo diagnose`` of a one-million-sample recording.

The recording is a concealed-effect recording of the simulated drive (a Dahl pivot of
0.2 mA with a 3 um Dahl length under the long-stroke scenario), 20 s at 50 kHz.  The
benchmark times the whole diagnosis (rows, baseline, every candidate of the vocabulary
over blocked cross-validation until none pays, quantisation test, the proof on the
held-out part with short-horizon simulations, locate tests), not the plots or the files.

What is asserted is a ratio, not seconds: the diagnosis against a reference workload of
the same kind timed just before and just after it in the same run (zero-phase filtering
and decimation of the recording's columns, where the diagnosis spends most of its time).  A neighbour that slows the machine slows both.  The
seconds are recorded (``bench/results/latest.json``) and, measured on a quiet machine,
in ``bench/README.md``.  Run with ``python -m pytest bench/test_diagnose.py -s``.

A second benchmark times what a user waits for after the interpreter has started: the
command's own work, ``servo diagnose REC.npz --out DIR`` run in-process (the recording
read, the diagnosis, the report, the four or five figures drawn beside it by a second
process, the page), against the same reference.
"""
import time

import numpy as np
import pytest
from scipy import signal

from servo.diagnose.concealed import Scenario, concealed_recording
from servo.diagnose.job import diagnose

SAMPLES = 1_000_000
REPEATS = 8
"""Timed repetitions of the reference before and after the diagnosis (median of all)."""
RATIO_MAX = 135.0
"""Diagnosis / reference.  Bound 135: 1.2x the worst of the merged code of 2026-11-28
(the Stribeck shape and bristle grid in), 111.9 idle (7.0 s, load 0.5), 95.8 beside two
busy processes (11.0 s; the reference slows more than the diagnosis there).  Before the
merge, bound 118 (round 4): 1.2x the worst ratio of
this code beside two busy processes (``python3 bench/load.py 2 -- env PYTHONPATH=$PWD
python -m pytest bench/test_diagnose.py -q -s``): 98.0 and 95.2 (45.7 and 43.2 s, load
10-14); 90.6 without them at load 10-12 (13.2 s).  The round's code before its last
change (the candidates sharing the current model's fit) read 87.8 at load 2-5 (9.8 s),
91.2 and 83.1 beside the busy processes.  The merged code before this round's
speed-ups read 100.4 near idle (6.2 s, load 1.6; 80-82 before the round's new stages).
History: 57.9-98.8 from 2026-11-23 to 2026-11-28 (bound 148, then 135); the code before
the compiled screens and the delay screen of 2026-11-23 measured 147.7-192.8.  Round 5
(the decimation filter's states in registers, the Stribeck bristle variants shortlisted;
docs/studies/2026-11-28-diagnose-speed-round5.md): 97.2-106.3 against the base's
100.0-113.7, alternated at load 4-26, where one code spreads by 10-25 %: not tightened."""


RATIO_COMMAND_MAX = 165.0
"""Command (files and figures written) / reference: the issue's goal, 6 s on the idle
2-core VM, is a ratio of 80-100 there (the reference took 60-76 ms idle).  The merged
code of 2026-11-28 read 131.5 idle (8.0 s, load 0.5) and 127.1 beside two busy
processes (12.6 s).  Bound 165
since 2026-11-28 (round 4): 1.2x the worst ratio of this round's code, 137.4 at load 2-5
(16.9 s, before its last change), above every run beside two busy processes (115.1,
117.7; with the last change 118.9 and 127.1, 54-56 s, load 8-14; 123.8 at load 10-12
without them): the figures are drawn on two processes, which a busy neighbour
serialises, so the command's ratio is worst under a light load.  The merged code before
this round read 143.8 near idle (8.8 s, load 1.6).  It fails when the figures cost as
much again as the diagnosis (drawn one after the other from every sample, they took 26 %
of the command before); the goal is not met.  Round 5: 105.3-146.5 against the base's
76.9-135.4, alternated at load 4-26 (one code spreads by 40 % there; not tightened)."""


@pytest.fixture(scope="module")
def million():
    rec, truth = concealed_recording("hysteresis", 2e-4, seed=1, scenario=Scenario(duration_s=SAMPLES / 50_000))
    assert rec.n == SAMPLES
    return rec


def reference_s(rec) -> float:
    """Seconds of the reference workload on ``rec``: four full-rate columns decimated by 10
    with a zero-phase Chebyshev filter (single-threaded, like most of the diagnosis: a
    threaded BLAS call would slow down under load far more than the diagnosis does)."""
    t0 = time.perf_counter()
    for c in (rec.u, rec.x, rec.u, rec.x):
        signal.decimate(np.asarray(c, float), 10, ftype="iir", zero_phase=True)
    return time.perf_counter() - t0


def test_diagnose_one_million_samples(benchmark, million, record):
    reference_s(million)  # warm
    before = [reference_s(million) for _ in range(REPEATS)]
    D = benchmark.pedantic(diagnose, args=(million,), rounds=1, iterations=1)
    after = [reference_s(million) for _ in range(REPEATS)]
    seconds = benchmark.stats.stats.max
    ref = float(np.median(before + after))
    before, after = float(np.median(before)), float(np.median(after))
    ratio = seconds / ref
    record.check("diagnose_1M_samples", seconds=seconds, reference_s=ref, ratio=ratio,
                 ratio_max=RATIO_MAX, samples=SAMPLES, findings=[f.physics for f in D.findings])  # fmt: skip
    print(f"\ndiagnose: {SAMPLES} samples in {seconds:.1f} s; reference {ref:.3f} s (medians {before:.3f} before, {after:.3f} after); "
          f"ratio {ratio:.1f} (bound {RATIO_MAX:g}); findings {[f.physics for f in D.findings]}")  # fmt: skip
    assert ratio < RATIO_MAX
    assert [f.physics for f in D.findings] == ["hysteresis"]
    assert np.isfinite(D.errors["test_output_nrmse"]["after"])


def test_diagnose_command_with_plots(million, record, tmp_path):
    """``servo diagnose REC.npz --out DIR`` in-process, every file written, over the reference."""
    from servo.cli import build_parser

    path = tmp_path / "million.npz"
    np.savez(path, t=million.t, u=million.u, x=million.x)
    out = tmp_path / "out"
    argv = ["diagnose", str(path), "--out", str(out)]
    args = build_parser().parse_args(argv)
    args.argv = ["servo", *argv]
    reference_s(million)  # warm
    before = [reference_s(million) for _ in range(REPEATS)]
    t0 = time.perf_counter()
    assert args.handler(args) in (None, 0)
    seconds = time.perf_counter() - t0
    after = [reference_s(million) for _ in range(REPEATS)]
    ref = float(np.median(before + after))
    ratio = seconds / ref
    figures = sorted(p.name for p in out.glob("*.png"))
    record.check("diagnose_command_1M_samples", seconds=seconds, reference_s=ref, ratio=ratio,
                 ratio_max=RATIO_COMMAND_MAX, samples=SAMPLES, figures=figures)  # fmt: skip
    print(f"\nservo diagnose (in-process, {len(figures)} figures): {SAMPLES} samples in {seconds:.1f} s; reference "
          f"{ref:.3f} s; ratio {ratio:.1f} (bound {RATIO_COMMAND_MAX:g})")  # fmt: skip
    assert ratio < RATIO_COMMAND_MAX
    assert {"residual_time.png", "residual_state.png", "residual_spectrum.png", "fits.png"} <= set(figures)
    assert (out / "report.html").stat().st_size > 0 and (out / "report.json").is_file()

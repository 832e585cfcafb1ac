"""The HDD benchmark through the project's runtime: the compiled loop with the "nss" and
"track" controller kinds reproduces the independent linear evaluation of servo.hdd
(scipy/control, exact lifted multirate loop) sample by sample, on the same disturbance
record."""
import tomllib
from pathlib import Path

import numpy as np
import pytest

from servo.config import Config
from servo.runtime.closedloop import MemoryLog
from servo.hdd import designs, linsim
from servo.hdd.benchmark import benchmark
from servo.hdd.disturbances import generate
from servo.scenarios.hdd_benchmark import BenchmarkInputs
from servo.hdd.drive import benchmark_drive
from servo.hdd.plant import plants
from servo.runtime.controller import Controller
from servo.runtime.loop import log_rows, run_closed_loop
from servo.runtime.simdriver import SimDriver

ROOT = Path(__file__).resolve().parents[1]
REVS = 30
#: The project's design as the example config runs it (its peak filters included).
TRACK = tomllib.loads((ROOT / "examples" / "hdd-track-v2.toml").read_text())["controller"]["track"]


def test_the_example_runs_the_documented_design():
    """``examples/hdd-track-v2.toml`` runs ``servo.hdd.designs.own(2)``, the design the
    linear evaluation tables (docs/hdd.md): the same sections, to rounding."""
    cfg = Config().replace(**benchmark_drive(2), controller={"kind": "track", "track": TRACK})
    ctl = Controller(cfg)
    ran = ctl.kind.designed(cfg.controller.section, cfg)
    own = designs.own(2)
    assert ran.pes_every == own.pes_every == 2 and ran.fs == pytest.approx(own.fs, rel=1e-12)
    assert ran.slow_sos.shape == own.slow_sos.shape == (5, 6)  # lead-lag + 4 peak filters
    assert ran.slow_sos == pytest.approx(own.slow_sos, rel=1e-9, abs=1e-12 * np.abs(own.slow_sos).max())
    assert ran.fast_sos == pytest.approx(own.fast_sos, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("kind", ["nss", "track"])
def test_the_compiled_loop_reproduces_the_linear_evaluation(kind):
    b = benchmark(2)
    over = benchmark_drive(2)
    over["drive"]["position_noise"] = 0.0  # the linear loop below gets the same (no) sensor noise
    over["run"]["duration_s"] = REVS * b.sectors * b.Ts
    cfg = Config().replace(**over, controller={"kind": kind, "track": TRACK}, scenario={"kind": "hdd_benchmark"})
    n = cfg.n_ticks
    dist = generate(n, 2, seed=cfg.run.seed, fs=cfg.run.sample_rate_hz)
    ctl = Controller(cfg)
    log = MemoryLog(log_rows(cfg), ctl.log_columns)
    inputs = BenchmarkInputs(dist)
    with SimDriver(cfg, inputs) as drv:
        run_closed_loop(cfg, drv, ctl, inputs, log, fast=True, timing=False)
    e = log.data[: log.rows, ctl.log_columns.index("e")]
    runtime_pes = -e[::2]  # PES = -e at the PES samples (even ticks), m

    design = ctl.kind.designed(cfg.controller.section, cfg)
    name, plant = plants(b, with_kf=False)[0]  # the nominal plant
    linear_pes = linsim.simulate(linsim.closed_loop(design, plant, b.Td), linsim.inputs(dist, include_noise=False))
    m = min(len(runtime_pes), len(linear_pes))
    a, c = runtime_pes[:m], linear_pes[:m]
    assert np.std(c) > 0.01 * b.Tp  # the runout is being followed, with a residual PES
    assert np.max(np.abs(a - c)) < 0.02 * np.std(c), (np.max(np.abs(a - c)) / np.std(c))

"""The ``hdd_benchmark`` scenario: follow a track with the NSS HDD benchmark's runout and
force disturbance (:mod:`servo.hdd.disturbances`)."""
from __future__ import annotations

from typing import TYPE_CHECKING

from servo.errors import ConfigError
from servo.scenarios.base import ArrayInputs, Inputs, ScenarioKind

if TYPE_CHECKING:
    from servo.hdd.disturbances import Disturbances


#: Most ticks a run of this scenario may last: its runout and force disturbance are
#: generated whole, ~6 float64 arrays as long as the run (~800 MB).
MAX_BENCHMARK_TICKS = 1 << 24


class BenchmarkInputs(ArrayInputs):
    """A run's inputs (:class:`~servo.scenarios.base.Inputs`) from :class:`~servo.hdd.disturbances.Disturbances`:
    reference ``-(RRO + flutter)`` held between PES samples; the force disturbance as the
    excitation current (``force_as="excitation"``, the default: added to the controller's
    command, it goes through the input delay and excites the flexible modes, as the
    benchmark's force disturbance does) or as the drive's disturbance force
    (``"disturbance"``: on the rigid body only, undelayed).  Sensor noise is the drive's
    ``position_noise`` (:func:`servo.hdd.drive.benchmark_drive` sets it)."""

    def __init__(self, dist: Disturbances, force_as: str = "excitation"):
        if force_as not in ("excitation", "disturbance"):
            raise ValueError(f"force_as = {force_as!r}: 'excitation' or 'disturbance'")
        kw = {"u_exc" if force_as == "excitation" else "d": dist.force}
        super().__init__(r=dist.reference(), **kw)
        self.dist = dist


class HddBenchmark(ScenarioKind):
    name = "hdd_benchmark"
    summary = "follow a track with the NSS HDD benchmark's disturbances (docs/hdd.md)"

    @classmethod
    def inputs(cls, cfg) -> Inputs:
        if cfg.n_ticks > MAX_BENCHMARK_TICKS:  # its disturbances are arrays as long as the run
            raise ConfigError(f"config: scenario.kind = hdd_benchmark holds its disturbances in memory, "
                              f"{cfg.n_ticks} ticks at {cfg.run.sample_rate_hz:g} Hz, more than {MAX_BENCHMARK_TICKS}; "
                              "shorten run.duration_s")  # fmt: skip
        from servo.hdd.disturbances import generate  # scipy.signal: imported when the kind is run, not registered

        try:
            dist = generate(cfg.n_ticks, cfg.scenario.hdd_version, seed=cfg.run.seed, fs=cfg.run.sample_rate_hz,
                            package=cfg.scenario.hdd_package or None)
        except ValueError as exc:
            raise ConfigError(f"config: scenario.kind = hdd_benchmark: {exc}") from None
        return BenchmarkInputs(dist)

    @classmethod
    def drive_defaults(cls, scenario) -> dict:
        """The benchmark's nominal plant of ``scenario.hdd_version`` (version 1 and 2 differ
        in the force constant and the flexible modes; their disturbances are the same)."""
        from servo.hdd.drive import benchmark_drive

        return benchmark_drive(scenario.hdd_version)["drive"]

    @classmethod
    def segments(cls, cfg) -> list[tuple[str, float, float]]:
        """The first 10 ms the benchmark ignores, then track following."""
        end = cfg.run.duration_s
        return [(name, a, b) for name, a, b in (("settling", 0.0, min(0.01, end)), ("track following", 0.01, end)) if a < end]

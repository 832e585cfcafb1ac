"""The NSS HDD servo benchmark: its plant as this project's drive, its disturbances, PES
figures (its linear evaluation of a design over the 54 plants is a study:
:mod:`studies.hdd.evaluate`).

* :func:`benchmark_drive`, :func:`perturbed_drives`: config overrides;
* :func:`generate`: the disturbances as arrays (as a run's inputs: the ``hdd_benchmark``
  scenario, :mod:`servo.scenarios.hdd_benchmark`);
* :func:`pes_figures`, :class:`PesAccumulator`: the PES figures;
"""
from servo.hdd.benchmark import Benchmark, benchmark
from servo.hdd.disturbances import Disturbances, generate
from servo.hdd.drive import benchmark_drive, perturbed_drives
from servo.hdd.pes import PesAccumulator, PesFigures, pes_figures

__all__ = ["Benchmark", "Disturbances", "PesAccumulator", "PesFigures", "benchmark",
           "benchmark_drive", "generate", "pes_figures", "perturbed_drives"]  # fmt: skip

"""The NSS HDD servo benchmark: its plant as this project's drive, its disturbances, PES
figures, and a linear evaluation of a :class:`~servo.design.Design` on it.

* :func:`benchmark_drive`, :func:`perturbed_drives`: config overrides;
* :func:`generate`, :class:`BenchmarkInputs`: disturbances as arrays and as run inputs;
* :func:`pes_figures`, :class:`PesAccumulator`: the PES figures;
* :func:`evaluate`: the benchmark's table for a design (``python -m servo.hdd.evaluate``).
"""
from servo.hdd.benchmark import Benchmark, benchmark
from servo.hdd.disturbances import BenchmarkInputs, Disturbances, generate
from servo.hdd.drive import benchmark_drive, perturbed_drives
from servo.hdd.pes import PesAccumulator, PesFigures, pes_figures

__all__ = ["Benchmark", "BenchmarkInputs", "Disturbances", "PesAccumulator", "PesFigures", "benchmark",
           "benchmark_drive", "generate", "pes_figures", "perturbed_drives"]  # fmt: skip

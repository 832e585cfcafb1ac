"""The benchmark as this project's simulated drive: config overrides.

The project's drive (``kernels/plant.py``) is ``J*x'' = u + d - B*x' - K*x - H - ...`` with
flexible modes ``q'' + 2*zeta*w*q' + w^2*q = u/J`` adding ``g*q`` to the measured
position.  The benchmark's plant is a sum of modes (:mod:`servo.hdd.benchmark`), the first
being the rigid body on its pivot (90 Hz, zeta 0.5, gain 1).  They are the same plant with

* ``J = m/Kf`` (A*s^2/m), ``K = J*w1^2``, ``B = 2*zeta1*w1*J`` (the pivot mode);
* the other six modes as ``drive.mode_*`` (the same ``u/J`` input and gains);
* no bias offset (``h0 = 0``), no Coulomb friction, and a pivot Dahl element of
  ``Ha = 1e-12`` A (the config needs one; it is 1e-8 of the force disturbance);
* the input delay ``Td`` (10 us, inside one tick at ``fs = 2/Ts``), no quantisation, the
  sensor noise of one PES sample (``position_noise``), no velocity measurement;
* the compensator off (there is no pivot nonlinearity to cancel; it would cancel the
  pivot mode, which is part of the benchmark's plant);
* a force-constant perturbation ``1 + d`` as ``J/(1 + d)`` with ``K`` and ``B`` following
  (the mode frequencies and damping do not move; every input is scaled by ``1 + d``).

``run.sample_rate_hz = 2/Ts`` (52.8 kHz): the tick is the benchmark's input period
``Tu = Ts/2``; a controller reads the PES every second tick.
"""
from __future__ import annotations

import math

from servo.hdd.benchmark import Benchmark, benchmark

#: The negligible pivot friction the config needs (its Dahl element must be > 0).
PIVOT_HA = 1e-12  # A
PIVOT_SIGMA = 1e-9  # A/m


def _drive(bench: Benchmark, hz, zeta, gain, d_kf: float) -> dict:
    if gain[0] != 1.0:
        raise ValueError("the rigid-body mode's gain must be 1 (the drive's rigid body has no gain of its own)")
    J = bench.J / (1 + d_kf)
    w1 = 2 * math.pi * hz[0]
    return dict(
        J=J, K=J * w1 * w1, B=2 * zeta[0] * w1 * J, h0=0.0, Fc=0.0, Fs=0.0, sigma=PIVOT_SIGMA, Ha=PIVOT_HA,
        alpha=1.0, mode_hz=[float(f) for f in hz[1:]], mode_zeta=[float(z) for z in zeta[1:]],
        mode_gain=[float(g) for g in gain[1:]], input_delay_s=bench.Td,
        position_noise=bench.sensor_noise * bench.Tp, position_quantum=0.0, velocity_noise=0.0,
        measures_velocity=False, kf_linear=0.0, kf_quadratic=0.0, cogging=0.0, initial_position=0.0,
    )  # fmt: skip


def benchmark_drive(version: int = 2) -> dict:
    """Config overrides ``{section: {key: value}}`` for the benchmark's nominal drive:
    ``[drive]``, ``[run] sample_rate_hz = 2/Ts`` and ``[compensator] enabled = false``.
    Use as ``Config().replace(**benchmark_drive())``."""
    b = benchmark(version)
    return dict(run=dict(sample_rate_hz=2.0 / b.Ts), drive=_drive(b, b.mode_hz, b.mode_zeta, b.mode_gain, 0.0),
                compensator=dict(enabled=False))  # fmt: skip


def perturbed_drives(version: int = 2, with_kf: bool = False) -> list[tuple[str, dict]]:
    """``(name, overrides)`` for every perturbed plant of the benchmark, nominal first
    (:meth:`~servo.hdd.benchmark.Benchmark.perturbations`): the 18 mechanical variants of
    version 2 (10 of version 1); ``with_kf`` adds the force-constant variants (+-10 %),
    54 (30) in all, the set the benchmark's evaluation runs."""
    b = benchmark(version)
    base = benchmark_drive(version)
    return [(name, dict(base, drive=_drive(b, hz, z, g, dk))) for name, hz, z, g, dk in b.perturbations(with_kf)]

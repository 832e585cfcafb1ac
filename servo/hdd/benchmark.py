"""The NSS HDD servo benchmark (HDD benchmark working group, M. Hirata, T. Hara et al.,
parameter files ``hdd_plantparam_v1/v2.m``, ``hdd_distparam_v1/v2.m``, 2007): its numbers.

Plant: current ``u`` (A) to head position ``y`` (m)::

    y = (Kf/m) * sum_i g_i / (s^2 + 2*zeta_i*w_i*s + w_i^2) * u(t - Td)

(the benchmark writes it in tracks, dividing by the track pitch ``Tp``).  Mode 1 is the
rigid body on its pivot (90 Hz, zeta 0.5).  Perturbed plants: every combination of the
rows of ``d_freq``, ``d_zeta`` and ``d_gain`` listed in ``combinations`` (18 in version
2, 10 in version 1), each also at the loop (force-constant) gains ``1 + d_kf``: the
benchmark's evaluation (``example1/evperf.m``) runs all ``len(combinations) *
len(d_kf)`` of them (54 in version 2, 30 in version 1).

Disturbances (see :mod:`servo.hdd.disturbances` for how they are generated): sensor
noise, a force disturbance at the plant input, disk flutter / suspension modes and
repeatable runout, with ``scl = sqrt(2*Ts)``.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Benchmark:
    """One version of the benchmark.  Frequencies in Hz, times in s, ``Tp`` in m, ``m`` in
    kg, ``Kf`` in N/A; perturbations as fractions (0.1 = +10 %); disturbance amplitudes in
    the benchmark's units (tracks, A) before the ``scl`` scaling."""

    version: int
    m: float
    Kf: float
    Tp: float
    rpm: float
    sectors: int
    Td: float
    mode_hz: tuple
    mode_zeta: tuple
    mode_gain: tuple
    d_freq: tuple  # rows of fractional shifts of every mode's frequency
    d_zeta: tuple
    d_gain: tuple
    combinations: tuple  # (freq row, zeta row, gain row), 0-based
    d_kf: tuple = (0.0, 0.10, -0.10)
    sensor_noise: float = 1.5e-2  # tracks, 1 sigma at Ts (times scl)
    force_noise: float = 1.0e-4  # A, 1 sigma at Ts (times scl)
    flutter_hz: tuple = (750, 780, 900, 1020, 1080, 1230, 1800, 3000, 5000)
    flutter_zeta: tuple = (0.01, 0.01, 0.01, 0.01, 0.005, 0.01, 0.005, 0.002, 0.002)
    flutter_amp: tuple = (0.09, 0.17, 0.20, 0.17, 0.06, 0.09, 0.06, 0.06, 0.12)  # tracks (times scl)
    rro_harmonics: tuple = (1, 2, 3)  # of the spindle frequency
    rro_amp: tuple = (0.15, 0.03, 0.006)  # tracks
    revolutions: int = 1000
    skip_s: float = 10e-3  # the benchmark ignores the first 10 ms of PES

    @property
    def Ts(self) -> float:
        """PES sample period (s): one servo sector."""
        return 60.0 / self.rpm / self.sectors

    @property
    def scl(self) -> float:
        """The benchmark's noise scaling ``sqrt(2*Ts)`` (sqrt(s))."""
        return float(np.sqrt(2 * self.Ts))

    @property
    def J(self) -> float:
        """Inertia in this project's units (A*s^2/m): ``m/Kf``."""
        return self.m / self.Kf

    @property
    def spindle_hz(self) -> float:
        return self.rpm / 60.0

    def perturbations(self, with_kf: bool = True) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray, float]]:
        """``(name, mode_hz, mode_zeta, mode_gain, d_kf)`` of every perturbed plant, the
        nominal first: the ``combinations`` at each ``d_kf`` (``with_kf``) or at ``d_kf = 0``.
        Names read ``P<i>`` (the benchmark's model number, 1-based) and ``K+10`` etc."""
        hz0, z0, g0 = (np.asarray(a, float) for a in (self.mode_hz, self.mode_zeta, self.mode_gain))
        out = []
        for dk in self.d_kf if with_kf else (0.0,):
            for i, (fi, zi, gi) in enumerate(self.combinations):
                name = f"P{i + 1}" + (f" K{dk * 100:+.0f}%" if with_kf and dk != 0 else "")
                out.append((name, hz0 * (1 + np.asarray(self.d_freq[fi])), z0 * (1 + np.asarray(self.d_zeta[zi])),
                            g0 * (1 + np.asarray(self.d_gain[gi])), dk))  # fmt: skip
        return out


V2 = Benchmark(
    version=2, m=1e-3, Kf=1.0, Tp=2.54e-7, rpm=7200.0, sectors=220, Td=10e-6,
    mode_hz=(90, 3000, 4100, 5000, 7000, 12300, 16400),
    mode_zeta=(0.5, 0.01, 0.03, 0.01, 0.01, 0.005, 0.005),
    mode_gain=(1.0, -0.01, -1.0, 0.3, -1.0, 1.0, -1.0),
    d_freq=((0, 0, 0, 0, 0, 0, 0), (0, 0.01, 0.025, 0.005, 0.005, 0.005, 0.005),
            (0, -0.02, -0.05, -0.02, -0.02, -0.02, -0.02)),
    d_zeta=((0,) * 7, (0, 0, 0, 0, -0.5, -0.5, -0.5), (0, 0, 0, 0, 1.0, 1.0, 1.0)),
    d_gain=((0,) * 7, (0, -2.0, 0.2, -2.0, 0, 0, 0)),
    combinations=tuple(itertools.product(range(3), range(3), range(2))),
)  # fmt: skip

V1 = Benchmark(
    version=1, m=1e-3, Kf=0.9512, Tp=2.54e-7, rpm=7200.0, sectors=220, Td=10e-6,
    mode_hz=(90, 4100, 8200, 12300, 16400, 3000, 5000),
    mode_zeta=(0.5, 0.02, 0.02, 0.02, 0.02, 0.005, 0.001),
    mode_gain=(1.0, -1.0, 1.0, -1.0, 1.0, 0.01, 0.03),
    d_freq=((0,) * 7, (0, 0.15, 0.15, 0.10, 0.10, 0.05, 0.05), (0, -0.15, -0.15, -0.10, -0.10, -0.05, -0.05),
            (0, 0.15, -0.15, -0.10, 0.10, 0.05, 0.05), (0, -0.15, 0.15, 0.10, -0.10, -0.05, -0.05)),
    d_zeta=((0,) * 7,),
    d_gain=((0,) * 7, (0, 0, 0, 0, 0, -2.0, -2.0)),
    combinations=tuple((f, 0, g) for f in range(5) for g in range(2)),
)  # fmt: skip

VERSIONS = {1: V1, 2: V2}


def benchmark(version: int = 2) -> Benchmark:
    """The benchmark's numbers for ``version`` (1 or 2)."""
    if version not in VERSIONS:
        raise ValueError(f"benchmark version {version!r}: 1 or 2")
    return VERSIONS[version]

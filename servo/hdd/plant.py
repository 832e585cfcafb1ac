"""A benchmark plant as a continuous state-space system (for the linear evaluation).

Every mode, the rigid body included, is ``q'' + 2*zeta*w*q' + w^2*q = b*u`` with
``b = (1 + d_kf)*Kf/m`` (m/s^2 per A) and adds ``g*q`` to the position (m); the state of a
mode is ``(w*q, q')`` so that the matrices stay well scaled (entries ~w, not w^2).
"""
from __future__ import annotations

import numpy as np

from servo.hdd.benchmark import Benchmark


def modal_ss(mode_hz, mode_zeta, mode_gain, b: float):
    """Continuous ``(A, B, C)`` of the sum of modes: current (A) to position (m)."""
    n = len(mode_hz)
    A = np.zeros((2 * n, 2 * n))
    B = np.zeros((2 * n, 1))
    C = np.zeros((1, 2 * n))
    for i, (f, z, g) in enumerate(zip(mode_hz, mode_zeta, mode_gain)):
        w = 2 * np.pi * f
        A[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = [[0.0, w], [-w, -2 * z * w]]
        B[2 * i + 1, 0] = b
        C[0, 2 * i] = g / w
    return A, B, C


def plants(bench: Benchmark, with_kf: bool = True) -> list[tuple[str, tuple]]:
    """``(name, (A, B, C))`` of every perturbed plant (:meth:`Benchmark.perturbations`),
    the nominal first; the input delay ``bench.Td`` is applied by the discretisation."""
    return [(name, modal_ss(hz, z, g, (1 + dk) * bench.Kf / bench.m))
            for name, hz, z, g, dk in bench.perturbations(with_kf)]  # fmt: skip

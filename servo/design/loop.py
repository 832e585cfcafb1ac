"""The exact loop of a :class:`~servo.design.design.Design` with a continuous plant, at the PES rate.

The sampled-data loop is: the PES ``y(k*Ts)`` sampled every ``Ts = pes_every/fs``; the
slow cascade; a hold over ``pes_every`` ticks; the fast cascade at ``fs``; a zero-order
hold at ``fs``; the plant ``x' = A x + B u(t - delay)``, ``y = C x``.  Everything after
the slow cascade up to the sampled PES is linear and time-invariant at the PES rate once
lifted (the held input is constant over ``pes_every`` ticks and the output is read at the
first tick of each PES period), so the open loop ``L(z)`` at the PES rate is exact: its
margins, crossover and closed-loop poles are those of the multirate loop, images included.

Systems here are plain ``(A, B, C, D)`` tuples of float64 arrays; :func:`open_loop`
returns a :class:`control.StateSpace`; :func:`margins` reads it by the one rule of
:mod:`servo.design.margins`.
"""
from __future__ import annotations

import math

import control
import numpy as np
from scipy import signal
from scipy.linalg import expm

from servo.design.design import Design
from servo.design.margins import margins as shared_margins


def _ss(A, B, C, D):
    return (np.atleast_2d(np.asarray(A, float)), np.atleast_2d(np.asarray(B, float)),
            np.atleast_2d(np.asarray(C, float)), np.atleast_2d(np.asarray(D, float)))  # fmt: skip


def series(first, second):
    """``second`` after ``first`` (both discrete, same rate): ``(A, B, C, D)``."""
    A1, B1, C1, D1 = first
    A2, B2, C2, D2 = second
    n1, n2 = A1.shape[0], A2.shape[0]
    A = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    B = np.vstack([B1, B2 @ D1])
    C = np.hstack([D2 @ C1, C2])
    return A, B, C, D2 @ D1


def cascade_ss(sos: np.ndarray):
    """A cascade of sections as one state-space system (section by section: no
    high-order polynomial is ever formed)."""
    out = _ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[1.0]])
    for row in np.asarray(sos).reshape(-1, 6):
        b, a = np.trim_zeros(row[:3], "b"), np.trim_zeros(row[3:], "b")
        n = max(len(b), len(a))
        b, a = np.pad(b, (0, n - len(b))), np.pad(a, (0, n - len(a)))
        out = series(out, _ss(*signal.tf2ss(b, a)) if n > 1 else _ss(np.zeros((0, 0)), np.zeros((0, 1)),
                                                                         np.zeros((1, 0)), [[b[0] / a[0]]]))  # fmt: skip
    return out


def zoh_delay(A, B, C, T: float, delay: float):
    """Zero-order-hold discretisation at period ``T`` of ``x' = A x + B u(t - delay)``,
    ``y = C x`` (single input), the delay exact: whole periods become a delay line, the
    remainder splits each period's integral in two.  Returns ``(A, B, C, D)`` at ``T``."""
    A, B, C = np.atleast_2d(A), np.reshape(B, (-1, 1)), np.atleast_2d(C)
    n = A.shape[0]
    m = int(math.floor(delay / T + 1e-9))
    frac = delay - m * T
    if frac < 1e-12 * T:
        frac = 0.0

    def integrals(h):
        M = np.zeros((n + 1, n + 1))
        M[:n, :n], M[:n, n:] = A * h, B * h
        E = expm(M)
        return E[:n, :n], E[:n, n:]

    Phi, G0 = integrals(T - frac)  # over the last part of the period: the newer input
    if frac > 0:
        Phi1, G1 = integrals(frac)  # first part: the older input
        Phi, G1, G0 = Phi @ Phi1, Phi @ G1, G0
    else:
        G1 = np.zeros((n, 1))
    # state: x, then the delay line u[k-1], ..., u[k-m-1] (m+1 entries when frac > 0)
    d = m + (1 if frac > 0 else 0)
    Ad = np.zeros((n + d, n + d))
    Bd = np.zeros((n + d, 1))
    Ad[:n, :n] = Phi
    if d == 0:
        Bd[:n] = G0
    else:
        # x[k+1] = Phi x + G0 u[k-m] + G1 u[k-m-1]
        if m == 0:
            Bd[:n] = G0
        else:
            Ad[:n, n + m - 1] = G0[:, 0]
        if frac > 0:
            Ad[:n, n + m] += G1[:, 0]
        Bd[n, 0] = 1.0
        for i in range(1, d):
            Ad[n + i, n + i - 1] = 1.0
    Cd = np.hstack([C, np.zeros((C.shape[0], d))])
    return Ad, Bd, Cd, np.zeros((C.shape[0], 1))


def lift(sys, n: int):
    """A fast-rate system with its input held over ``n`` periods and its output read at
    the first of them: the same system at ``n`` times the period (exact)."""
    A, B, C, D = sys
    An = np.eye(A.shape[0])
    Bn = np.zeros_like(B)
    for _ in range(n):
        Bn = A @ Bn + B
        An = A @ An
    return An, Bn, C, D


def double_integrator(J: float):
    """``J*x'' = u`` (J in A*s^2/m): continuous ``(A, B, C)`` from current (A) to position (m)."""
    return np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0 / J]]), np.array([[1.0, 0.0]])


def plant_after_controller(design: Design, plant, delay_s: float = 0.0):
    """Hold, fast cascade, zero-order hold, plant with its delay, PES sampling: the path
    from the slow cascade's output (A) to the sampled position (m), lifted to the PES rate."""
    A, B, C = plant
    fast = series(cascade_ss(design.fast_sos), zoh_delay(A, B, C, 1.0 / design.fs, delay_s))
    return lift(fast, design.pes_every)


def open_loop(design: Design, plant, delay_s: float = 0.0) -> control.StateSpace:
    """``L(z)`` at the PES rate: slow cascade then :func:`plant_after_controller`, for the
    loop ``e = r - y`` (negative feedback closes it).  ``plant``: continuous ``(A, B, C)``
    from current (A) to position (m)."""
    L = series(cascade_ss(design.slow_sos), plant_after_controller(design, plant, delay_s))
    return control.ss(*L, 1.0 / design.fs_pes)


def frequency_response(L: control.StateSpace, f_hz, chunk: int = 1024) -> np.ndarray:
    """``L(exp(j*2*pi*f*dt))`` at ``f_hz`` (Hz): ``C (zI - A)^-1 B + D`` solved at every
    frequency (batched; no diagonalisation, since a loop with an integrator on a double
    integrator has a defective triple pole at ``z = 1``)."""
    A, B, C, D = (np.asarray(m, float) for m in (L.A, L.B, L.C, L.D))
    f = np.asarray(f_hz, float)
    z = np.exp(2j * np.pi * f.ravel() * L.dt)
    n = A.shape[0]
    out = np.full(z.shape, D[0, 0], complex)
    if n:
        eye = np.eye(n)
        for i in range(0, z.shape[0], chunk):
            zz = z[i : i + chunk]
            x = np.linalg.solve(zz[:, None, None] * eye - A, np.broadcast_to(B[:, :1], (zz.shape[0], n, 1)))
            out[i : i + chunk] += np.einsum("j,kj->k", C[0], x[..., 0])
    return out.reshape(f.shape)


def margins(L: control.StateSpace, n: int = 20000) -> dict:
    """Margins of the loop ``L`` (negative feedback) by the one rule of
    :func:`servo.design.margins.margins`, over the whole band: the frequency response on
    ``n`` log-spaced points from ``1e-5`` of the PES Nyquist frequency up to it, every
    crossing and peak refined on the exact response, the closed loop's stability and
    pole radius from the poles of ``L/(1+L)`` (an unstable loop gets no margins)."""
    fn = 0.5 / L.dt
    f = np.geomspace(fn * 1e-5, fn, n)
    cl = control.feedback(L, 1)
    radius = float(np.max(np.abs(cl.poles()))) if cl.nstates else 0.0
    return shared_margins(f, frequency_response(L, f), dense=True, response=lambda x: frequency_response(L, x),
                          nyquist_hz=fn, stable=radius < 1.0, pole_radius=radius)  # fmt: skip

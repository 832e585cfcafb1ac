"""The benchmark's multirate loop as one linear system at the PES rate, simulated and solved.

Independent of the project's runtime: plant (:mod:`servo.hdd.plant`) discretised exactly
at the tick period with its input delay, the fast cascade at the tick rate, the slow
cascade at the PES rate, lifted (:mod:`servo.design.loop`) into one discrete system with

* inputs ``[w_o, d_0 .. d_{N-1}]``: ``w_o`` what is added to the head position in the
  PES (runout + sensor noise, m), ``d_j`` the force disturbance (A) during tick ``j`` of
  the PES period (``N = pes_every``), added to the command before the delay;
* output: the PES ``y + w_o`` (m), the benchmark's sign (the controller acts on ``-PES``).

:func:`simulate` runs it on a disturbance record (a compiled state-space recursion);
:func:`stationary_nrro` gives the PES variance of the random disturbances exactly
(discrete Lyapunov equation), :func:`rro_response` the steady RRO.
"""
from __future__ import annotations

import numpy as np
from numba import float64, njit
from scipy import linalg, signal

from servo.design.design import Design
from servo.design.loop import cascade_ss, zoh_delay
from servo.hdd.benchmark import Benchmark
from servo.hdd.disturbances import Disturbances, flutter_filters


def closed_loop(design: Design, plant, delay_s: float):
    """``(A, B, C, D)`` of the closed loop at the PES rate (module doc); ``plant``
    continuous ``(A, B, C)`` current (A) to position (m)."""
    AF, BF, CF, DF = cascade_ss(design.fast_sos)
    AP, BP, CP, _ = zoh_delay(*plant, 1.0 / design.fs, delay_s)
    nF, nP = AF.shape[0], AP.shape[0]
    A = np.block([[AF, np.zeros((nF, nP))], [BP @ CF, AP]])
    Bv = np.vstack([BF, BP @ DF])
    Bd = np.vstack([np.zeros((nF, 1)), BP])
    C = np.hstack([np.zeros((1, nF)), CP])
    N = design.pes_every
    powers = [np.eye(A.shape[0])]
    for _ in range(N):
        powers.append(A @ powers[-1])
    AN = powers[N]
    Bs_v = sum(powers[N - 1 - j] @ Bv for j in range(N))
    Bs_d = [powers[N - 1 - j] @ Bd for j in range(N)]
    AK, BK, CK, DK = cascade_ss(design.slow_sos)
    nx, nk = A.shape[0], AK.shape[0]
    Acl = np.block([[AN - Bs_v @ DK @ C, Bs_v @ CK], [-BK @ C, AK]])
    Bcl = np.zeros((nx + nk, 1 + N))
    Bcl[:nx, :1] = -Bs_v @ DK
    Bcl[nx:, :1] = -BK
    for j in range(N):
        Bcl[:nx, 1 + j : 2 + j] = Bs_d[j]
    Ccl = np.hstack([C, np.zeros((1, nk))])
    Dcl = np.zeros((1, 1 + N))
    Dcl[0, 0] = 1.0
    return Acl, Bcl, Ccl, Dcl


@njit(float64[::1](float64[:, ::1], float64[:, ::1], float64[::1], float64[::1], float64[:, ::1]), cache=True)
def _simulate(A, B, C, D, U):
    n, m = A.shape[0], B.shape[1]
    steps = U.shape[0]
    y = np.empty(steps)
    x = np.zeros(n)
    xn = np.zeros(n)
    for k in range(steps):
        acc = 0.0
        for i in range(n):
            acc += C[i] * x[i]
        for j in range(m):
            acc += D[j] * U[k, j]
        y[k] = acc
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += A[i, j] * x[j]
            for j in range(m):
                s += B[i, j] * U[k, j]
            xn[i] = s
        for i in range(n):
            x[i] = xn[i]
    return y


def inputs(dist: Disturbances, include_noise: bool = True) -> np.ndarray:
    """The closed loop's input record ``(n_pes, 1 + pes_every)`` from a disturbance record."""
    N = dist.pes_every
    n_pes = dist.rro.shape[0]
    U = np.zeros((n_pes, 1 + N))
    U[:, 0] = dist.runout + (dist.noise if include_noise else 0.0)
    f = np.zeros(n_pes * N)
    f[: dist.force.shape[0]] = dist.force
    U[:, 1:] = f.reshape(n_pes, N)
    return U


def simulate(cl, U: np.ndarray) -> np.ndarray:
    """PES (m) of the closed loop ``cl`` (:func:`closed_loop`) from rest under ``U``."""
    A, B, C, D = cl
    return _simulate(np.ascontiguousarray(A), np.ascontiguousarray(B), np.ascontiguousarray(C[0]),
                     np.ascontiguousarray(D[0]), np.ascontiguousarray(U, dtype=float))  # fmt: skip


def stationary_nrro(cl, bench: Benchmark, dist: Disturbances) -> dict:
    """Stationary PES standard deviation (m) of each random disturbance and of all of them
    (``"total"``), exactly, from the closed loop ``cl`` and the disturbance models:
    flutter (its resonances at ``Ts``), sensor noise (``dist.noise_std``), force
    (``dist.force_std`` per tick)."""
    A, B, C, D = cl
    Ts = bench.Ts
    out = {}
    # flutter: resonances (ss at Ts) feeding w_o
    fl = [signal.tf2ss(np.trim_zeros(b, "f"), a) for b, a in flutter_filters(bench)]
    nf = sum(f[0].shape[0] for f in fl)
    n = A.shape[0]
    Aa = np.zeros((n + nf, n + nf))
    Aa[:n, :n] = A
    Ba = np.zeros((n + nf, len(fl)))
    Ca = np.zeros((1, n + nf))
    Ca[0, :n] = C[0]
    Da = np.zeros((1, len(fl)))
    i = n
    for j, (Af, Bf, Cf, Df) in enumerate(fl):
        k = Af.shape[0]
        Aa[i : i + k, i : i + k] = Af
        Ba[i : i + k, j] = Bf[:, 0]
        Aa[:n, i : i + k] = B[:, :1] @ Cf * bench.Tp
        Ba[:n, j] = B[:, 0] * Df[0, 0] * bench.Tp
        Ca[0, i : i + k] = Cf[0] * D[0, 0] * bench.Tp
        Da[0, j] = D[0, 0] * Df[0, 0] * bench.Tp
        i += k
    q = 1.0 / (2 * Ts)  # variance of the unit-PSD white samples at Ts
    P = linalg.solve_discrete_lyapunov(Aa, q * Ba @ Ba.T)
    out["flutter"] = float(np.sqrt((Ca @ P @ Ca.T + q * Da @ Da.T)[0, 0]))
    for name, cols, var in (("noise", [0], dist.noise_std**2),
                            ("force", list(range(1, B.shape[1])), dist.force_std**2)):  # fmt: skip
        Bn = B[:, cols]
        P = linalg.solve_discrete_lyapunov(A, var * Bn @ Bn.T)
        out[name] = float(np.sqrt((C @ P @ C.T + var * D[:, cols] @ D[:, cols].T)[0, 0]))
    out["total"] = float(np.sqrt(sum(v * v for v in out.values())))
    return out


def sensitivity(cl, f_hz, fs_pes: float) -> np.ndarray:
    """The transfer from ``w_o`` (runout) to PES at ``f_hz`` (Hz): the output sensitivity."""
    A, B, C, D = cl
    out = []
    for f in np.atleast_1d(f_hz):
        z = np.exp(2j * np.pi * f / fs_pes)
        out.append((C @ np.linalg.solve(z * np.eye(A.shape[0]) - A, B[:, :1]))[0, 0] + D[0, 0])
    return np.array(out)


def rro_response(cl, bench: Benchmark, dist: Disturbances, fs_pes: float) -> np.ndarray:
    """The steady PES (m) over one revolution due to the RRO (``(sectors,)``): the
    revolution's harmonics (``dist.rro_revolution``, DFT) each through the sensitivity."""
    n = bench.sectors
    spec = np.fft.rfft(dist.rro_revolution)
    s = sensitivity(cl, np.arange(spec.shape[0]) * fs_pes / n, fs_pes)
    return np.fft.irfft(spec * s, n)

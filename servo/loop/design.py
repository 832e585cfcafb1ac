"""The designed loop: the controller's linear response times the plant's, as sampled.

Both are responses of the sampled loop at the tick instants (``z = exp(j*w*dt)``), the
quantities a stepped-sine measurement at the ticks estimates:

* :func:`controller_response` -- ``C``, from ``-x`` to the controller's output (the
  compensator excluded: it belongs to the plant it linearises, eq. 10);
* :func:`plant_response` -- ``P``, from the current command to the measured position:
  the nominal compensated plant ``1/(J*s^2)`` (``model="nominal"``) or the simulated
  drive's linear model (``model="drive"``), each sampled with the zero-order hold, the
  drive's input delay (whole and fractional samples, as :mod:`kernels.plant` applies it)
  and the link's command latency;
* :func:`loop_design` -- ``L = C*P``, ``S = 1/(1+L)``, ``T = L/(1+L)``;
* :func:`current_loop_design` -- the same broken at the current, where the compensator
  counts as feedback (small-signal, :func:`compensator_response`).

Signs: the controller's feedback output is ``u_fb = -C*x`` (negative feedback), so the
loop broken at the controller's output is ``L = C*P`` (see docs/loop.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.linalg import expm

from servo.config import Config
from servo.runtime.simplant import split_delay

#: Plant models of :func:`plant_response`.
PLANT_MODELS = ("nominal", "drive")


def _z(cfg: Config, f_hz) -> np.ndarray:
    return np.exp(2j * np.pi * np.asarray(f_hz, dtype=float) * cfg.dt)


def uses_measured_velocity(cfg: Config) -> bool:
    """Whether the controller's rate feedback reads the drive's velocity sensor (else
    its own estimator on the position), as :func:`servo.runtime.controller.stage_params`
    and the drive decide it."""
    return cfg.controller.velocity_source == "auto" and cfg.drive.measures_velocity


def controller_response(cfg: Config, f_hz) -> np.ndarray:
    """The linear frequency response ``C(f)`` (A/m, complex, shape of ``f_hz``) of the
    configured controller kind from ``-x`` (m) to its output ``u_n`` (A), as it runs at
    the tick rate: the kind's own :meth:`~servo.controllers.ControllerKind.response`
    (for the PI holding loop, ``kp + ki*dt/(z - 1) + kd*D(z)`` with ``D`` the velocity
    signal per unit position: ``j*w`` when the drive's velocity is measured, else the
    estimator's).  The output limits are assumed inactive."""
    from servo.controllers import get_kind

    with np.errstate(divide="ignore", invalid="ignore"):
        return get_kind(cfg.controller.kind).response(cfg.controller.section, cfg, np.asarray(f_hz, dtype=float))


def compensator_response(cfg: Config, f_hz) -> np.ndarray:
    """The compensator's small-signal response (A/m, complex, shape of ``f_hz``) from
    ``x`` to ``u_c`` in its SLOW regime near a turnaround (eq. 9 with the Dahl estimate
    on its pre-sliding slope)::

        F(z) = K + sigma + B*D(z)

    with the ``[compensator]`` estimates and ``D`` the velocity signal of
    :func:`controller_response`.  Valid while the motion stays well inside
    ``Ha/sigma`` and below ``fast_on_speed``; the FAST regime's Coulomb term has no
    linear response.
    """
    k = cfg.compensator
    f = np.asarray(f_hz, dtype=float)
    if uses_measured_velocity(cfg):
        d = 2j * np.pi * f
    else:
        z = _z(cfg, f)
        a = math.exp(-2.0 * math.pi * cfg.controller.velocity_cutoff_hz * cfg.dt)
        d = (1.0 - a) * (1.0 - 1.0 / z) / cfg.dt / (1.0 - a / z)
    return k.K + k.sigma + k.B * d


def _gamma(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``(exp(a*h), int_0^h exp(a*t) dt b)`` by one augmented matrix exponential."""
    n = a.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n] = a
    m[:n, n] = b
    e = expm(m * h)
    return e[:n, :n], e[:n, n]


def _state_space(cfg: Config, model: str, compensated: bool, stiffness: float | None):
    """Continuous ``(A, b, c)`` of the plant from current (A) to measured position (m)."""
    d = cfg.drive
    J = d.J
    if model == "nominal":
        k, damp = 0.0, 0.0
        hz, zeta, gain = (), (), ()
    elif model == "drive":
        k = 0.0 if compensated else d.K + (d.sigma if stiffness is None else stiffness)
        damp = 0.0 if compensated else d.B
        hz, zeta, gain = d.mode_hz, d.mode_zeta, d.mode_gain
    else:
        raise ValueError(f"unknown plant model {model!r} (one of {', '.join(PLANT_MODELS)})")
    n = 2 + 2 * len(hz)
    a = np.zeros((n, n))
    b = np.zeros(n)
    c = np.zeros(n)
    a[0, 1] = 1.0
    a[1, 0] = -k / J
    a[1, 1] = -damp / J
    b[1] = 1.0 / J
    c[0] = 1.0
    for i, (f, z, g) in enumerate(zip(hz, zeta, gain)):
        w = 2.0 * math.pi * f
        j = 2 + 2 * i
        a[j, j + 1] = 1.0
        a[j + 1, j] = -w * w
        a[j + 1, j + 1] = -2.0 * z * w
        b[j + 1] = 1.0 / J
        c[j] = g
    return a, b, c


def plant_response(cfg: Config, f_hz, model: str = "nominal", compensated: bool = True,
                   stiffness: float | None = None) -> np.ndarray:  # fmt: skip
    """The sampled plant ``P(f)`` (m/A, complex, shape of ``f_hz``) from the command of
    tick k to the position measured at the ticks.

    ``model="nominal"``: the double integrator ``1/(J*s^2)`` that the compensator leaves
    (eq. 10).  ``model="drive"``: the simulated drive's linear model, the rigid body plus
    its flexible modes (``drive.mode_*``, measured position ``x + sum(g_i*q_i)``); with
    ``compensated=False`` the rigid body keeps the viscous friction ``drive.B`` and the
    stiffness ``drive.K`` plus the pivot's small-signal stiffness (``stiffness``, A/m;
    default ``drive.sigma``, the pre-sliding slope of the Dahl element, valid while the
    motion stays well inside ``Ha/sigma``); with the compensator those cancel.

    Sampling as the simulated drive applies the command: held over the sample (zero-order
    hold), delayed by ``drive.input_delay_s`` (whole samples and a fraction) and by
    the link's latency in the loop (:attr:`~servo.config.LinkConfig.loop_latency_ticks`:
    none with the loop on the board).  Exact for the linear model (matrix exponentials of
    the two constant-input pieces of each sample, :func:`servo.runtime.simplant.mode_matrices`
    does the same for the modes).
    """
    return sampled_plant(cfg, model, compensated, stiffness)(f_hz)


def sampled_plant(cfg: Config, model: str = "nominal", compensated: bool = True,
                  stiffness: float | None = None) -> Callable[[np.ndarray], np.ndarray]:  # fmt: skip
    """:func:`plant_response` as a function of the frequencies (Hz), its sampled
    matrices computed once (for a caller that evaluates it many times)."""
    a, b, c = _state_space(cfg, model, compensated, stiffness)
    dt = cfg.dt
    whole, frac = split_delay(cfg.drive.input_delay_s, dt)
    phi2, g2 = _gamma(a, b, dt - frac)  # second piece: this sample's command
    phi1, g1 = _gamma(a, b, frac)  # first piece: the previous one
    phi = phi2 @ phi1
    g_prev = phi2 @ g1
    n = a.shape[0]
    lag = whole + cfg.link.loop_latency_ticks

    def response(f_hz) -> np.ndarray:
        f = np.asarray(f_hz, dtype=float)
        z = _z(cfg, f).ravel()
        out = np.full(z.shape, np.inf, dtype=complex)  # z = 1 on an integrating plant stays inf
        g = (g_prev[None, :] / z[:, None] + g2[None, :]) * (z**-lag)[:, None]
        m = z[:, None, None] * np.eye(n) - phi
        ok = np.abs(np.linalg.det(m)) > 0
        if ok.any():
            out[ok] = np.linalg.solve(m[ok], g[ok][..., None])[..., 0] @ c
        return out.reshape(f.shape)

    return response


@dataclass
class LoopDesign:
    """The designed loop at ``f_hz`` (Hz, (n,)): ``C`` (A/m), ``P`` (m/A), ``L = C*P``,
    ``S = 1/(1+L)``, ``T = L/(1+L)`` (complex (n,)); ``model`` names the plant."""

    f_hz: np.ndarray
    C: np.ndarray
    P: np.ndarray
    model: str

    @property
    def L(self) -> np.ndarray:
        return self.C * self.P

    @property
    def S(self) -> np.ndarray:
        return 1.0 / (1.0 + self.L)

    @property
    def T(self) -> np.ndarray:
        return self.L / (1.0 + self.L)


def loop_design(cfg: Config, f_hz, model: str = "nominal", compensated: bool = True,
                stiffness: float | None = None) -> LoopDesign:  # fmt: skip
    """The designed loop of ``cfg`` at ``f_hz``: :func:`controller_response` times
    :func:`plant_response` (arguments as there)."""
    f = np.asarray(f_hz, dtype=float)
    label = model if model == "nominal" else f"drive, {'compensated' if compensated else 'small-signal pivot'}"
    return LoopDesign(f, controller_response(cfg, f), plant_response(cfg, f, model, compensated, stiffness), label)


def current_loop_design(cfg: Config, f_hz, compensated: bool = True) -> LoopDesign:
    """The small-signal loop broken at the current ``u`` (``L_u = -U_fb/U``): the
    feedback is the controller and the compensator, ``u_fb = -C*x + F*x``
    (:func:`compensator_response`, 0 when not ``compensated``), around the drive with its
    pivot on the pre-sliding slope (``plant_response(model="drive", compensated=False)``)::

        L_u = (C - F)*P_drive

    Without the compensator it is the controller-output loop of the drive model."""
    f = np.asarray(f_hz, dtype=float)
    fb = controller_response(cfg, f) - (compensator_response(cfg, f) if compensated else 0.0)
    label = "at the current, small-signal pivot" + (" and compensator" if compensated else "")
    return LoopDesign(f, fb, plant_response(cfg, f, "drive", compensated=False), label)


def design_grid(cfg: Config, f_min: float, f_max: float, n: int = 2000) -> np.ndarray:
    """A dense log-spaced grid (Hz) for a design's curves and margins: a decade either
    side of ``[f_min, f_max]``, below Nyquist."""
    hi = min(10.0 * f_max, 0.499 / cfg.dt)
    return np.geomspace(max(f_min / 10.0, 1e-3), hi, n)


__all__ = ["PLANT_MODELS", "LoopDesign", "compensator_response", "controller_response", "current_loop_design",
           "design_grid", "loop_design", "plant_response", "sampled_plant",
           "uses_measured_velocity"]

"""Continuous-time building blocks of a track-following controller, as zeros, poles, gain.

Every block is a :class:`Block`: its zeros and poles (rad/s, complex), its gain, a name
and the rate it will run at once discretised (``"slow"``: the PES rate; ``"fast"``: the
tick rate).  Frequencies are in Hz at the interface, rad/s inside.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Block:
    """``k * prod(s - z) / prod(s - p)``: ``z``, ``p`` in rad/s; ``rate`` "slow" or "fast";
    ``match_hz`` the frequency (Hz) a discretisation keeps exact (bilinear prewarp, matched
    gain); ``params`` what it was built from (for documentation)."""

    name: str
    z: np.ndarray
    p: np.ndarray
    k: float
    rate: str
    match_hz: float
    params: dict = field(default_factory=dict)

    def response(self, f_hz) -> np.ndarray:
        """Continuous frequency response at ``f_hz`` (Hz)."""
        s = 2j * np.pi * np.asarray(f_hz, dtype=float)
        h = np.full(s.shape, self.k, dtype=complex)
        for z in self.z:
            h *= s - z
        for p in self.p:
            h /= s - p
        return h


def _pair(w: float, zeta: float) -> np.ndarray:
    """The two roots of ``s^2 + 2*zeta*w*s + w^2`` (zeta in (0, 1))."""
    return np.array([complex(-zeta * w, w * math.sqrt(1 - zeta * zeta)), complex(-zeta * w, -w * math.sqrt(1 - zeta * zeta))])


def notch(f_hz: float, depth_db: float, width: float) -> Block:
    """Notch ``(s^2 + 2*zz*w*s + w^2) / (s^2 + 2*zp*w*s + w^2)``, ``w = 2*pi*f_hz``.

    ``depth_db`` (> 0): attenuation at the centre, ``|N(jw)| = zz/zp = 10**(-depth_db/20)``;
    ``width`` (> 0): relative bandwidth, ``zp = width/2`` (a deep notch's -3 dB band is
    about ``width*f_hz`` Hz wide).  Unity gain at DC and at infinity."""
    if not (f_hz > 0 and depth_db > 0 and 0 < width < 2):
        raise ValueError(f"notch ({f_hz}, {depth_db}, {width}): need f_hz > 0, depth_db > 0, 0 < width < 2")
    w = 2 * math.pi * f_hz
    zp = width / 2
    zz = zp * 10 ** (-depth_db / 20)
    return Block(f"notch {f_hz:g} Hz", _pair(w, zz), _pair(w, zp), 1.0, "fast", f_hz,
                 dict(f_hz=f_hz, depth_db=depth_db, width=width, zeta_zero=zz, zeta_pole=zp))  # fmt: skip


def peak(f_hz: float, gain_db: float, width: float, phase_deg: float = 0.0) -> Block:
    """Peak filter ``1 + k*e^(j*phi)`` at its centre: ``1 + P(s)`` with the resonance
    ``P(s) = k * 2*zeta*w * (s*cos(phi) - w*sin(phi)) / (s^2 + 2*zeta*w*s + w^2)``,
    ``w = 2*pi*f_hz``, ``zeta = width/2``, ``k = 10**(gain_db/20) - 1``::

        (s^2 + 2*zeta*w*(1 + k*cos(phi))*s + w^2*(1 - 2*zeta*k*sin(phi))) / (s^2 + 2*zeta*w*s + w^2)

    Placed in series with a loop ``L`` it adds ``L*P`` in parallel: the sensitivity at the
    centre becomes ``S / (1 + T*P)``, lowered where ``T*P`` is near the positive real axis.
    ``gain_db`` (> 0): the peak's gain at the centre for ``phase_deg = 0``; ``width``
    (> 0): relative bandwidth (``2*zeta``); ``phase_deg``: the phase ``phi`` of ``P`` at
    the centre, chosen against ``T``'s phase there (a *phase-stable insertion*: ``phi``
    near ``-angle(T)`` keeps the added loop stable; 0 below the crossover, where ``T`` is
    near 1).  Unity gain at DC and at infinity (when ``phi = 0``)."""
    if not (f_hz > 0 and gain_db > 0 and 0 < width < 2 and -90.0 <= phase_deg <= 90.0):
        raise ValueError(f"peak ({f_hz}, {gain_db}, {width}, {phase_deg}): need f_hz > 0, gain_db > 0, 0 < width < 2, "
                         "-90 <= phase_deg <= 90")  # fmt: skip
    w = 2 * math.pi * f_hz
    zeta = width / 2
    k = 10 ** (gain_db / 20) - 1
    phi = math.radians(phase_deg)
    zeros = np.roots([1.0, 2 * zeta * w * (1 + k * math.cos(phi)), w * w * (1 - 2 * zeta * k * math.sin(phi))])
    return Block(f"peak {f_hz:g} Hz", np.asarray(zeros, complex), _pair(w, zeta), 1.0, "slow", f_hz,
                 dict(f_hz=f_hz, gain_db=gain_db, width=width, phase_deg=phase_deg))  # fmt: skip


def lowpass(f_hz: float, zeta: float = 0.7) -> Block:
    """Second-order low-pass ``w^2 / (s^2 + 2*zeta*w*s + w^2)``, unity DC gain."""
    if not (f_hz > 0 and 0 < zeta < 1):
        raise ValueError(f"low-pass ({f_hz}, {zeta}): need f_hz > 0 and 0 < zeta < 1")
    w = 2 * math.pi * f_hz
    return Block(f"low-pass {f_hz:g} Hz", np.zeros(0, complex), _pair(w, zeta), w * w, "fast", f_hz,
                 dict(f_hz=f_hz, zeta=zeta))  # fmt: skip


def lead_integrator(crossover_hz: float, lead_ratio: float, integrator_ratio: float | None, gain: float) -> Block:
    """Lead-lag with an integrator, centred on the crossover ``wc = 2*pi*crossover_hz``::

        C(s) = gain * (s + wi)/s * (1 + s/wz)/(1 + s/wp),  wz = wc/sqrt(a), wp = wc*sqrt(a)

    ``lead_ratio`` ``a = wp/wz >= 1`` (phase lead ``asin((a-1)/(a+1))`` at ``wc``);
    ``integrator_ratio`` ``wc/wi`` (None: no integrator, ``(s + wi)/s`` -> 1).  The same
    transfer function is a PID with a filtered derivative (``params`` lists its
    ``kp``, ``ki``, ``kd`` and the derivative filter's corner)."""
    if not lead_ratio >= 1:
        raise ValueError(f"lead ratio {lead_ratio} must be >= 1")
    wc = 2 * math.pi * crossover_hz
    wz, wp = wc / math.sqrt(lead_ratio), wc * math.sqrt(lead_ratio)
    z, p, k = [-wz], [-wp], gain * wp / wz
    params = dict(crossover_hz=crossover_hz, lead_ratio=lead_ratio, integrator_ratio=integrator_ratio,
                  gain=gain, lead_zero_hz=wz / (2 * math.pi), lead_pole_hz=wp / (2 * math.pi))  # fmt: skip
    if integrator_ratio:
        wi = wc / integrator_ratio
        z.append(-wi)
        p.append(0.0)
        params["integrator_hz"] = wi / (2 * math.pi)
        # gain*(1 + wi/s)*(1 + s/wz)/(1 + s/wp) = kp + ki/s + kd*s/(1 + s/wp)
        params["ki"] = gain * wi
        params["kp"] = gain * (1 + wi / wz - wi / wp)
        params["kd"] = gain * (1 / wz - 1 / wp) * (1 - wi / wp)
    else:
        params["kp"] = gain
        params["kd"] = gain * (1 / wz - 1 / wp)
    params["derivative_filter_hz"] = wp / (2 * math.pi)
    return Block("lead-lag + integrator", np.array(z, complex), np.array(p, complex), k, "slow", crossover_hz, params)

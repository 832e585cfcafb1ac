"""Discretisation of a continuous :class:`~servo.design.analog.Block` to second-order sections.

Three methods (the user picks one for a whole design):

``bilinear``
    Tustin with prewarping at the block's ``match_hz``: the analog prototype is scaled in
    frequency so that the digital response at ``match_hz`` equals the analog one exactly
    (a notch keeps its centre and depth, the lead its phase at the crossover).
``matched``
    Poles and zeros mapped by ``z = exp(s/fs)``; zeros at infinity (a low-pass) go to
    ``z = -1``; the gain matches the analog magnitude at DC, or at ``match_hz`` when the
    block has a pole or zero at ``s = 0`` (an integrator).
``zoh``
    Zero-order-hold equivalent (``scipy.signal.cont2discrete``): the block's step
    response at the sample instants.  It does not map a notch's zeros: a 20 dB notch at
    4.1 kHz comes out about 12 dB deep at 52.8 kHz (use it for the lead-lag only).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from servo.design.analog import Block

METHODS = ("bilinear", "matched", "zoh")


def _digital(z, p, k, f_hz, fs):
    zi = np.exp(-2j * np.pi * f_hz / fs)
    num = k * np.prod([1 - zz * zi for zz in z]) if len(z) else k
    den = np.prod([1 - pp * zi for pp in p]) if len(p) else 1.0
    return num / den * zi ** (len(p) - len(z))


def zpk(block: Block, fs: float, method: str) -> tuple[np.ndarray, np.ndarray, float]:
    """Digital ``(zeros, poles, gain)`` of ``block`` at sample rate ``fs`` (Hz)."""
    if method not in METHODS:
        raise ValueError(f"discretisation method {method!r}: one of {', '.join(METHODS)}")
    if block.match_hz >= fs / 2:
        raise ValueError(f"{block.name}: {block.match_hz:g} Hz is at or above Nyquist ({fs / 2:g} Hz) of its rate")
    z, p, k = np.asarray(block.z, complex), np.asarray(block.p, complex), float(block.k)
    if method == "bilinear":
        w0 = 2 * math.pi * block.match_hz
        c = w0 / (2 * fs * math.tan(w0 / (2 * fs)))  # H'(s) = H(c*s) matches H at w0 after Tustin
        zd, pd, kd = signal.bilinear_zpk(z / c, p / c, k * c ** (len(z) - len(p)), fs)
        return np.asarray(zd), np.asarray(pd), float(np.real(kd))
    if method == "zoh":
        zd, pd, kd, _ = signal.cont2discrete((z, p, k), 1.0 / fs, method="zoh")
        zd = np.asarray(zd, complex)
        zd = zd[np.isfinite(zd)]
        return zd, np.asarray(pd, complex), float(np.real(kd))
    zd = np.concatenate([np.exp(z / fs), -np.ones(max(len(p) - len(z), 0))])
    pd = np.exp(p / fs)
    f = 0.0 if not (np.any(np.abs(z) == 0) or np.any(np.abs(p) == 0)) else block.match_hz
    ha = block.response(np.array(f))
    hd = _digital(zd, pd, 1.0, f, fs)
    ratio = ha / hd
    return zd, pd, float(abs(ratio) * (1.0 if ratio.real >= 0 else -1.0))


def sos(block: Block, fs: float, method: str) -> np.ndarray:
    """The block as second-order sections (n, 6) at ``fs`` (Hz) by ``method``."""
    zd, pd, kd = zpk(block, fs, method)
    return signal.zpk2sos(zd, pd, kd)

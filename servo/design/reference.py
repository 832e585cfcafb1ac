"""The NSS HDD benchmark's own track-following design, as a :class:`Design`.

The benchmark's design example (``example1/followdemo.m``, for its version-1 plant) is a
discrete PID at the PES period ``Ts`` on the PES in tracks::

    C(z) = [P*(z^2 - z) + I*z + D*(z^2 - 2z + 1)] / (z^2 - z) / g
         = [P*(1 - z^-1) + I*z^-1 + D*(1 - z^-1)^2] / (1 - z^-1) / g

(note the integral term is ``I*z^-1``, one PES sample late, in the benchmark's code), with
``P = 2, I = 0.05, D = 70, g = 1.665e3`` (tracks to A), followed by four notch filters
run at ``Ts/2`` (the PID output held for two input samples).  Here the PES is in metres,
so ``C`` is divided by the track pitch ``Tp``.

The benchmark gives its notches as discrete state-space matrices at ``Ts/2`` (4 digits).
Mapped back to continuous time (``s = ln(z)/T``), their poles and zeros sit at the named
centres with DC gain 1, and their Nyquist gain is not 1 (0.90 at the 12.3 kHz notch):
they are *matched* discretisations (``z = exp(sT)``) of the notch
:func:`servo.design.analog.notch` with

==========  ==========  ===========================================
centre, Hz  depth, dB   width (``2*zeta_pole``)
==========  ==========  ===========================================
4100        10          0.412
5000        20          0.272
8200        20          0.724
12300       20          0.606
==========  ==========  ===========================================

which :func:`nss_reference` uses by default (its notches match the benchmark's matrices
to the 4 digits they are given with; ``tests/test_design.py`` checks it).
"""
from __future__ import annotations

import numpy as np

from servo.design import analog, discretise
from servo.design.design import Design

#: Track pitch of the benchmark (m), 100 kTPI.
TRACK_PITCH = 2.54e-7

#: The benchmark's notches: (centre Hz, depth dB, relative width), see the module doc.
NSS_NOTCHES = ((4100.0, 10.0, 0.412), (5000.0, 20.0, 0.272), (8200.0, 20.0, 0.724), (12300.0, 20.0, 0.606))


def pid_sos(P: float, I: float, D: float, g: float, Tp: float) -> np.ndarray:
    """The benchmark's PID as one section, PES in metres to current in A."""
    b = np.array([P + D, I - P - 2 * D, D]) / (g * Tp)
    return np.array([[*b, 1.0, -1.0, 0.0]])


def nss_reference(
    fs_pes: float,
    Tp: float = TRACK_PITCH,
    P: float = 2.0,
    I: float = 0.05,  # noqa: E741 (the benchmark's name)
    D: float = 70.0,
    g: float = 1.665e3,
    notch_hz=tuple(n[0] for n in NSS_NOTCHES),
    notch_depth_db=tuple(n[1] for n in NSS_NOTCHES),
    notch_width=tuple(n[2] for n in NSS_NOTCHES),
    pes_every: int = 2,
    method: str = "matched",
) -> Design:
    """The benchmark's reference design: PID at ``fs_pes`` (Hz; the benchmark's is
    ``1/Ts = 26.4 kHz``), notches at ``pes_every*fs_pes`` (2: the benchmark's ``Ts/2``).

    ``Tp``: track pitch (m); ``P, I, D, g``: the benchmark's PID (PES in tracks, current
    = C/g); ``notch_hz``, ``notch_depth_db``, ``notch_width``: the notches
    (:func:`servo.design.analog.notch`), by default the benchmark's (module doc);
    ``method``: their discretisation ("matched" reproduces the benchmark's)."""
    fs = fs_pes * pes_every
    if not (len(notch_hz) == len(notch_depth_db) == len(notch_width)):
        raise ValueError("notch_hz, notch_depth_db and notch_width must have the same length")
    blocks = tuple(analog.notch(f, dd, w) for f, dd, w in zip(notch_hz, notch_depth_db, notch_width))
    fast = np.vstack([discretise.sos(b, fs, method) for b in blocks]) if blocks else np.zeros((0, 6))
    info = dict(kind="nss_reference", P=P, I=I, D=D, g=g, Tp=Tp,
                pid="C(z) = [P(1-z^-1) + I z^-1 + D(1-z^-1)^2] / (1-z^-1) / (g Tp)")  # fmt: skip
    return Design(pid_sos(P, I, D, g, Tp), fast, fs, pes_every, integrators=1, blocks=(), method=method, info=info)

"""Holding-loop gains for experiments: a PID with rate feedback placed at a bandwidth.

The default holding loop (``servo/config.py``) sits at 100 Hz.  Experiments that need the
arm to move freely at their excitation frequency (the square-wave identification) use a
slower loop that only stops the drift; :func:`holding_gains` gives the gains of the same
structure at another bandwidth (``kp = J*w^2``, ``ki = J*w^3/5``, ``kd = 2*0.7*J*w``).
"""
from __future__ import annotations

import math


def holding_gains(J: float, hz: float, damping: float = 0.7) -> dict[str, float]:
    """Controller fields ``kp`` (A/m), ``ki`` (A/(m*s)), ``kd`` (A*s/m) of a holding loop at
    ``hz`` on the double integrator ``J*x'' = u`` (``J`` in A*s^2/m)."""
    w = 2.0 * math.pi * hz
    return {"kp": J * w * w, "ki": J * w**3 / 5.0, "kd": 2.0 * damping * J * w}

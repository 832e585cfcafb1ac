"""An input delay: the command reaches the arm ``delay_s`` later than recorded.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import math

import numpy as np

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, Search, SignalPath, Term


class Delay(SignalPath):
    """The delay on the input's path, after the amplifier's clipping; the frequency-domain
    path fits ``delay_s`` (log-spaced: no)."""

    def transform(self, u, theta, dt):
        k = np.arange(u.size, dtype=float)
        return np.interp(k - theta["delay_s"] / dt, k, u)

    @staticmethod
    def frf_factor(theta, f, dt):
        """The delay's factor on the input-to-position response at ``f`` (k,) Hz:
        ``exp(-j*2*pi*f*delay_s)``, flat magnitude and a phase linear in frequency (the
        frequency-domain path's hook, :func:`servo.diagnose.frf_modes.input_path`)."""
        return np.exp(-2j * np.pi * np.asarray(f, dtype=float) * theta["delay_s"])


class DelaySearch(Search):
    """A delay refined within a sample, tried on top of a model from the force filtered once."""

    def refine_width(self, d, name, value):
        return d.sig.dt  # one sample

    def screen_target(self, d, model, theta):
        """A delay tried on top of a model without one: interpolated from the force filtered
        once (the design's :meth:`~servo.diagnose.model.Design.delayed_force`, equal to the
        exact chain's rows to rounding); None beyond the shifts it holds."""
        shift = theta["delay_s"] / d.sig.dt
        df = d.delayed_force(model)
        return df.rows(shift) if abs(shift) <= df.max_shift else None


class TimeDelay(Term):
    name, thetas, units = "time_delay", ("delay_s",), {"delay_s": "s"}
    doc = "the input reaches the arm delay_s later than recorded (negative: the log lags the motion)"
    path = Delay(kind="input", path_order=1, frf_param="delay_s")
    search = DelaySearch()

    def _range(self, d):
        q = d.sig.settings.decimate
        return -q * d.sig.dt, 2 * q * d.sig.dt

    def grid(self, d, model):
        """Twentieths of a sample up to half a sample, quarter samples up to two either
        way, whole samples beyond (a 0.1-sample delay on a lead-lag loop was missed with
        quarter samples alone: 17/20 of the proving ground's delays, 20/20 with tenths;
        a sensor low-pass at ``fs/2``, a one-pole whose mean delay is 0.045 samples, lost
        an open-loop PRBS's every fold to the no-delay variant with tenths, and a
        heavily damped "mode" took its place).  The no-delay variant stays in the grid."""
        q = d.sig.settings.decimate
        steps = sorted({j / 20 for j in range(-10, 11)} | {j / 4 for j in range(-8, 9)} | (set(range(-q, 2 * q + 1)) - {0}))
        return [{"delay_s": j * d.sig.dt} for j in steps]

    def bounds(self, d, model):
        return {"delay_s": (*self._range(d), False)}


class TimeDelayDrive(DriveMap):
    """The time_delay term in the simulated drive's ``[drive]`` section."""

    name = "time_delay"
    absent = {"input_delay_s": 0.0}

    def to_drive(self, P, fit):
        return {"input_delay_s": P[self.name]["delay_s"]}

    def from_drive(self, d):
        return [({"delay_s": d.input_delay_s}, ())] if d.input_delay_s > 0 else []


def _conceal(size):
    return {"input_delay_s": size}


_STUDY = Concealment("time_delay", "s", "input delay", (1e-6, 2e-6, 3e-6, 5e-6, 1e-5), 2e-5, fields=_conceal)


def split_delay(delay_s: float, dt: float) -> tuple[int, float]:
    """Input delay as ``(whole samples, remainder in s)`` with the remainder in ``[0, dt)``."""
    n = delay_s / dt
    whole = math.floor(round(n, 9))
    frac = delay_s - whole * dt
    if frac < 1e-12 * dt:
        frac = 0.0
    return whole, frac


def _plant(d, dt):
    whole, frac = split_delay(d.input_delay_s, dt)
    return {"delay_frac": frac, "delay_whole": whole}


EFFECT = Effect(
    "time_delay", "input delay (amplifier and computation)",
    drive=dict(input_delay_s=P(10e-6, "s", "input delay (amplifier + computation)", 0.0, 0.1)),
    plant=_plant,
    term=TimeDelay(),
    not_cancellable="an input delay cannot be cancelled by a static term: use a predictor (a Smith predictor on "
                    "the delay) or keep the crossover well below 1/(2*pi*delay)",
    drive_map=TimeDelayDrive(),
    study=_STUDY,
    simulated=lambda d, sim: {"input_delay_s": 0.0},  # applied to the input beforehand
)  # fmt: skip

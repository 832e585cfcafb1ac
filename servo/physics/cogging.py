"""A force periodic in position (cogging): ``amplitude*sin(2*pi*x/period + phase)``.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import math

import numpy as np

from servo.fields import P
from servo.physics.base import (Concealment, DriveMap, Effect, Judging, Search, Term, contiguous, fold_ranges,
                                number, valid_speed)


class CoggingSearch(Search):
    """The large grid of periods screened by complex rotation, uniform in wavenumber."""

    def screen(self, d, theta, model):
        w = 2 * math.pi * d.sig.x_rows / theta["period"]
        return np.column_stack([np.sin(w), np.cos(w)])

    def screen_batch(self, d, thetas, model):
        """sin/cos of ``2*pi*x/period`` for a chunk of the (uniform in 1/period) grid,
        (J, 2, m), by complex rotation instead of one sine per variant."""
        k = np.array([1.0 / th["period"] for th in thetas])
        x = d.sig.x_rows
        if k.size > 2 and np.allclose(np.diff(k), k[1] - k[0], rtol=1e-9, atol=0):
            # one complex row at a time, written straight into the output (a (J, m)
            # complex block besides it doubled the memory of a chunk)
            out = np.empty((k.size, 2, x.size))
            z = np.exp(2j * math.pi * x * k[0])
            step = np.exp(2j * math.pi * x * (k[1] - k[0]))
            for j in range(k.size):
                if j:
                    np.multiply(z, step, out=z)
                out[j, 0], out[j, 1] = z.imag, z.real
            return out
        z = np.exp(2j * math.pi * k[:, None] * x[None, :])
        return np.stack([z.imag, z.real], axis=1)

    def screen_sums(self, d, thetas, model, r, blocks):
        """A uniform grid of wavenumbers by rotation, row tile by row tile
        (:func:`kernels.screen.cogging_stats`); None for another grid."""
        k = np.array([1.0 / th["period"] for th in thetas])
        if k.size < 3 or not np.allclose(np.diff(k), k[1] - k[0], rtol=1e-9, atol=0):
            return None
        starts, stops = fold_ranges(blocks)
        K, J = starts.size, k.size
        a, H = np.empty((K, J, 2)), np.empty((K, J, 2, 2))
        dk = (k[-1] - k[0]) / (J - 1)
        from kernels.screen import cogging_stats

        cogging_stats(contiguous(d.sig.x_rows), contiguous(r), contiguous(blocks.weights), starts, stops, float(k[0]), float(dk), a, H)
        return a, H


class CoggingJudging(Judging):
    """The amplitude's std from the two coefficients'."""

    def std_extra(self, params, std):
        if "a_sin" in std and "a_cos" in std:
            return {"amplitude": float(np.hypot(std["a_sin"], std["a_cos"]) / np.sqrt(2))}
        return {}


class Cogging(Term):
    name, coefs, thetas = "cogging", ("a_sin", "a_cos"), ("period",)
    units = {"a_sin": "F", "a_cos": "F", "period": "m", "amplitude": "F", "phase": "rad"}
    doc = "a force periodic in position: amplitude*sin(2*pi*x/period + phase)"
    MAX_GRID = 3000
    search = CoggingSearch()
    judging = CoggingJudging()

    def full(self, d, theta, u_eff):
        w = 2 * math.pi * d.sig.xf / theta["period"]
        return np.column_stack([np.sin(w), np.cos(w)])

    def _k_range(self, d):
        s = d.sig
        span = float(np.ptp(s.x_rows[d.train_rows]))
        v25 = float(np.quantile(valid_speed(d), 0.25))
        k_hi = min(0.35 / s.row_dt / max(v25, 1e-300), 1.0 / (20.0 * max(s.noise_x, 1e-300)))
        return 2.0 / span, k_hi, span

    def grid(self, d, model):
        k_lo, k_hi, span = self._k_range(d)
        if k_hi <= k_lo:
            return []
        n = int(min(self.MAX_GRID, math.ceil((k_hi - k_lo) * 3 * span) + 1))
        return [{"period": float(1.0 / k)} for k in np.linspace(k_lo, k_hi, n)]

    def bounds(self, d, model):
        k_lo, k_hi, _ = self._k_range(d)
        return {"period": (1.0 / k_hi, 1.0 / k_lo, True)}

    def physical(self, theta, coef):
        a, b = map(float, coef)
        return {"amplitude": math.hypot(a, b), "period": float(theta["period"]), "phase": math.atan2(b, a),
                "a_sin": a, "a_cos": b}  # fmt: skip

    def from_physical(self, p):
        A, ph = p["amplitude"], p.get("phase", 0.0)
        return {"period": p["period"]}, (A * math.cos(ph), A * math.sin(ph))


class CoggingDrive(DriveMap):
    """The cogging term in the simulated drive's ``[drive]`` section."""

    name = "cogging"

    def to_drive(self, P, fit):
        c = P[self.name]
        return {"cogging": c["amplitude"], "cogging_period": c["period"], "cogging_phase": c["phase"]}

    def from_drive(self, d):
        if not d.cogging:
            return []
        A, ph = d.cogging, d.cogging_phase  # as Cogging.from_physical
        return [({"period": d.cogging_period}, (A * math.cos(ph), A * math.sin(ph)))]


def _conceal(size):
    return {"cogging": size, "cogging_period": 50e-6}


def _leave_out(d):
    d["cogging"] = 0.0


_STUDY = Concealment("cogging", "A", "cogging amplitude (period 50 um)", (1e-6, 2e-6, 5e-6, 1e-5, 2e-5), 1e-4,
                     fields=_conceal)


def _stage(c):
    n = len(c.periodic_amplitudes)
    from kernels.cancel import harmonic_coefficients

    sin, cos = harmonic_coefficients(c.periodic_amplitudes, c.periodic_phases)
    return {"n_per": n, "per_period": c.periodic_period, "per_sin": sin, "per_cos": cos}


EFFECT = Effect(
    "cogging", "a force periodic in position",
    drive=dict(
        cogging=P(0.0, "A", "amplitude of a force periodic in position", 0.0),
        cogging_period=P(1.0e-4, "m", "period of that force", 0.0, None, lo_open=True),
        cogging_phase=P(0.0, "rad", "phase of that force", -2 * math.pi, 2 * math.pi),
    ),
    compensator=dict(
        periodic_amplitudes=P([], "A", "force periodic in position, amplitude of harmonics 1, 2, ... (at most 4; "
                              "cancels drive.cogging)", 0.0),
        periodic_phases=P([], "rad", "their phases", -2 * math.pi, 2 * math.pi),
        periodic_period=P(1.0e-4, "m", "the fundamental period in position", 0.0, None, lo_open=True),
    ),
    plant=lambda d, dt: {"cog_amp": d.cogging, "cog_period": d.cogging_period, "cog_phase": d.cogging_phase},
    stage=_stage,
    engaged=lambda c: bool(c.periodic_amplitudes),
    term=Cogging(),
    drive_map=CoggingDrive(),
    leave_out=_leave_out,
    study=_STUDY,
    simulated=lambda d, sim: {"cogging": d.get("cogging", 0.0), "cogging_period": d.get("cogging_period", 1.0),
                              "cogging_phase": d.get("cogging_phase", 0.0)},
    cancel=lambda d, how: [] if how.paper or not number(d, "cogging") else [("force periodic in position", dict(
        periodic_amplitudes=[number(d, "cogging")], periodic_phases=[number(d, "cogging_phase")],
        periodic_period=number(d, "cogging_period", 1e-4)))],
    rest_force=lambda d, x: d.cogging * math.sin(2.0 * math.pi * x / d.cogging_period + d.cogging_phase),
    forces=lambda f, stroke, speed: {"periodic force's amplitude": abs(number(f, "cogging")) + sum(
        abs(a) for a in f.get("periodic_amplitudes", []))},
)  # fmt: skip

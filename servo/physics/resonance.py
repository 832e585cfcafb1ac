"""Lightly damped flexible modes in the measured position.

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

import math

import numpy as np

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, Judging, Search, SignalPath, Term, contiguous, fold_ranges


class ModeSearch(Search):
    """Up to :attr:`Resonance.MAX_MODES` modes; a grid screened by its biquads over the
    force rows."""

    def eligible(self, model):
        n = sum(t.physics == self.term.name for t in model.terms)
        return None if n < self.term.MAX_MODES else f"{n} modes already in the model"

    def screen(self, d, theta, model):
        from scipy import signal

        y = d.target_raw(model)
        b, a = self.term.biquad(theta["frequency_hz"], theta["zeta"], 1.0 / d.sig.row_dt)
        return -signal.lfilter(b, a, y)[:, None]

    def screen_sums(self, d, thetas, model, r, blocks):
        """All variants' biquads run over the force rows together (:func:`kernels.screen.biquad_stats`)."""
        fs = 1.0 / d.sig.row_dt
        BA = [self.term.biquad(th["frequency_hz"], th["zeta"], fs) for th in thetas]
        B = np.ascontiguousarray(np.array([b for b, _ in BA], dtype=float).T)  # (3, J)
        A = np.ascontiguousarray(np.array([a for _, a in BA], dtype=float).T)
        starts, stops = fold_ranges(blocks)
        K, J = starts.size, len(thetas)
        a, H = np.empty((K, J, 1)), np.empty((K, J, 1, 1))
        y = np.ascontiguousarray(d.target_raw(model), dtype=float)
        from kernels.screen import biquad_stats

        biquad_stats(y, contiguous(r), contiguous(blocks.weights), starts, stops, B, A, -1.0, a, H)
        return a, H


class ModeJudging(Judging):
    """A mode at the damping bound is no lightly damped mode."""

    def implausible(self, params: dict) -> str:
        if params["zeta"] >= 0.95 * self.term.ZETA_MAX:
            return (f"the best mode sits at the damping bound (zeta {params['zeta']:.3g}): what the data show is not a "
                    "lightly damped mode (a delay or a filter acts like a heavily damped one)")  # fmt: skip
        return ""


class Resonance(Term):
    name, coefs, thetas = "resonance", ("gain",), ("frequency_hz", "zeta")
    units = {"gain": "-", "frequency_hz": "Hz", "zeta": "-"}
    doc = ("a lightly damped mode in the measured position, x_meas = x + gain*q with "
           "q'' + 2*zeta*w*q' + w^2*q = u/J: in the force balance, -gain*s^2/(s^2 + 2*zeta*w*s + w^2) u")  # fmt: skip
    path = SignalPath(uses_input=True)
    ZETAS = (0.005, 0.02, 0.06)
    ZETA_MAX = 0.1  # a lightly damped mode
    MAX_MODES = 4
    search = ModeSearch()
    judging = ModeJudging()

    @staticmethod
    def biquad(f: float, zeta: float, fs: float):
        """``s^2/(s^2 + 2*zeta*w*s + w^2)`` by the bilinear transform prewarped at ``f``."""
        w = 2 * math.pi * f
        k = w / math.tan(w / (2 * fs))
        a0 = k * k + 2 * zeta * w * k + w * w
        b = np.array([k * k, -2 * k * k, k * k]) / a0
        a = np.array([1.0, (2 * w * w - 2 * k * k) / a0, (k * k - 2 * zeta * w * k + w * w) / a0])
        return b, a

    def full(self, d, theta, u_eff):
        from scipy import signal  # here: a run imports this module, scipy.signal only a diagnosis

        s = d.sig
        b, a = self.biquad(theta["frequency_hz"], theta["zeta"], 1.0 / s.dt)
        return -signal.lfilter(b, a, s.force(u_eff))

    def _range(self, d):
        s = d.sig
        T = s.row_dt * max(int(np.count_nonzero(d.train_rows)), 1)
        return max(20.0 / T, 1.0 / (200 * s.row_dt)), 0.35 / s.row_dt

    def grid(self, d, model):
        lo, hi = self._range(d)
        out = []
        for z in self.ZETAS:
            n = max(2, int(math.ceil(math.log(hi / lo) / math.log(1 + z))) + 1)
            out += [{"frequency_hz": float(f), "zeta": z} for f in np.geomspace(lo, hi, n)]
        return out

    def bounds(self, d, model):
        lo, hi = self._range(d)
        return {"frequency_hz": (lo, hi, True), "zeta": (0.001, self.ZETA_MAX, True)}

    @staticmethod
    def frf_mode(J: float, hz: float, zeta: float, f, dt: float):
        """The mode's own response of unit gain at ``f`` (k,) Hz, ``1/(J (s^2 + 2 zeta w s
        + w^2))`` through a zero-order hold sampled every ``dt`` (``zeta < 1``: distinct
        poles ``l``, ``sum r/l (p - 1)/(z - p)`` with ``p = exp(l*dt)``, the
        step-invariant transform in closed form); complex (k,).  The frequency-domain
        path's hook (:mod:`servo.diagnose.frf_modes`): a measured response is the rigid
        body plus ``gain`` times this per mode."""
        w = 2 * math.pi * hz
        wd = w * math.sqrt(max(1.0 - zeta * zeta, 1e-12))
        l1 = complex(-zeta * w, wd)
        l2 = l1.conjugate()
        r1 = 1.0 / (J * (l1 - l2))
        z = np.exp(2j * np.pi * np.asarray(f, dtype=float) * dt)
        h = 0.0
        for lam, r in ((l1, r1), (l2, -r1)):
            p = np.exp(lam * dt)
            h = h + (r / lam) * (p - 1.0) / (z - p)
        return h

class ResonanceDrive(DriveMap):
    """The resonance term in the simulated drive's ``[drive]`` section."""

    name = "resonance"
    absent = {"mode_hz": [], "mode_zeta": [], "mode_gain": []}

    def to_drive(self, P, fit):
        d = {"mode_hz": [], "mode_zeta": [], "mode_gain": []}
        for i, t in enumerate(fit.model.terms):  # every mode, not their sum
            if t.physics == self.name:
                q = fit.term_params(i)
                d["mode_hz"].append(q["frequency_hz"])
                d["mode_zeta"].append(q["zeta"])
                d["mode_gain"].append(q["gain"])
        return d

    def from_drive(self, d):
        return [({"frequency_hz": f, "zeta": z}, (g,)) for f, z, g in zip(d.mode_hz, d.mode_zeta, d.mode_gain)]


def _conceal(size):
    return {"mode_hz": [700.0], "mode_zeta": [0.02], "mode_gain": [size]}


_STUDY = Concealment("resonance", "-", "modal gain of a 700 Hz, zeta 0.02 mode", (2e-4, 5e-4, 1e-3, 2e-3, 5e-3), 0.05,
                     fields=_conceal)


EFFECT = Effect(
    "resonance", "flexible modes: x_meas = x + gain*q, q'' + 2*zeta*w*q' + w^2*q = u/J",
    drive=dict(
        mode_hz=P([3000.0, 4100.0, 5000.0, 7000.0, 12300.0, 16400.0], "Hz", "flexible mode frequencies", 0.0, None,
                  lo_open=True),
        mode_zeta=P([0.01, 0.03, 0.01, 0.01, 0.005, 0.005], "-", "flexible mode damping ratios", 0.0, 10.0, lo_open=True),
        mode_gain=P([-0.01, -1.0, 0.3, -1.0, 1.0, -1.0], "-", "flexible mode gains (x_meas += g*q)", -100.0, 100.0),
    ),
    term=Resonance(),
    not_cancellable="a flexible mode cannot be cancelled by a static term: notch it in the controller "
                    "([controller.track] notch_hz) or keep the crossover below it",
    drive_map=ResonanceDrive(),
    study=_STUDY,
    simulated=lambda d, sim: {"mode_hz": [], "mode_zeta": [], "mode_gain": []},  # stepped apart (mode_trace)
    diagnosed_by="frf",
)  # fmt: skip

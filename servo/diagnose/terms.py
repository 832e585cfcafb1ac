"""The vocabulary of physics a diagnosis can name: one small object per term.

Each term is parametric, with a physical name, and contributes to the force balance
``u_eff = sum coef * column`` (see :mod:`servo.diagnose.model`) in one of three ways:

* ``column`` terms add regressor columns, linear in their coefficients ``coefs`` for
  fixed nonlinear parameters ``thetas`` (a Stribeck velocity, a Dahl length, a mode's
  frequency and damping, a cogging period).  The columns are built at full rate from the
  filtered motion and passed through the rows' parallel filter.
* ``input`` terms transform the recorded input before it reaches the arm (a saturation
  level, a delay); they change the target, not the columns.
* the ``sensor`` term (quantisation) changes neither: see :mod:`servo.diagnose.quantization`.

Forces are in the recording's force unit ``F`` (A of VCM current, or N), positions in m.
For each term: ``rows(design, theta, u_eff)`` the exact rows (m, k); ``grid(design,
model)`` the nonlinear parameters a diagnosis tries (``[{}]`` for a linear term);
``screen(design, theta, model)`` a fast approximation of the rows used to scan large
grids; ``bounds`` for the final refinement; ``physical``/``from_physical`` between the
internal ``(theta, coef)`` and the reported parameters.

Each term also owns what the rest of the tool needs to know about it: ``to_drive`` /
``absent`` / ``from_drive`` its fields in the simulated drive's ``[drive]`` section (the
final model written as a config, its short-horizon simulation, a drive config held as a
model file), ``std_extra`` the uncertainty of its derived parameters, and ``effect`` /
``conceal`` how the concealed-effect study (:mod:`servo.diagnose.concealed`) puts it into
a drive.  Adding a term is one class here and one entry in :data:`VOCABULARY`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from kernels.hysteresis import dahl_trace
from kernels.screen import biquad_stats, cogging_stats
from servo.fields import MAGNITUDE_MAX

#: every physics name a finding can carry, in the order the docs list them
NAMES = (
    "inertia", "viscous_friction", "coulomb_friction", "stiffness", "offset", "asymmetric_friction",
    "stribeck_friction", "hysteresis", "resonance", "time_delay", "sensor_lag", "input_saturation",
    "position_dependent_gain", "cogging", "quantization",
)  # fmt: skip


@dataclass(frozen=True)
class Effect:
    """How the concealed-effect study (:mod:`servo.diagnose.concealed`) hides a term in the
    null drive: the ``physics`` a diagnosis should name, the size's ``unit`` and meaning
    (``what``), the sizes of the detection study, a clearly detectable size for the tests,
    the baseline to diagnose with and drive fields ``fixed`` at every size."""

    physics: str
    unit: str
    what: str
    sizes: tuple
    clear: float
    baseline: str = "J,B,Fc,K,h0"
    fixed: dict = field(default_factory=dict)

    def drive(self, size: float) -> dict:
        """The ``[drive]`` fields of the effect at ``size``."""
        return {**self.fixed, **VOCABULARY[self.physics].conceal(size)}


class Physics:
    """Base: a linear term with one column and no nonlinear parameter."""

    name = ""
    kind = "column"
    coefs: tuple = ()
    thetas: tuple = ()
    units: dict = {}
    doc = ""
    requires: tuple = ()
    uses_input = False
    screening = False  # large grids scanned with fast approximate rows

    def full(self, d, theta: dict, u_eff: np.ndarray) -> np.ndarray:
        """Full-rate columns (n, k)."""
        raise NotImplementedError

    def rows(self, d, theta: dict, u_eff: np.ndarray) -> np.ndarray:
        F = np.atleast_2d(self.full(d, theta, u_eff).T).T
        return np.column_stack([d.sig.rows(np.ascontiguousarray(F[:, j])) for j in range(F.shape[1])])

    def screen(self, d, theta: dict, model) -> np.ndarray:
        return d.variant_rows(self.name, theta, model)

    def screen_batch(self, d, thetas: list, model) -> np.ndarray:
        """Approximate rows of several variants at once, (J, k, m)."""
        return np.stack([np.atleast_2d(self.screen(d, th, model).T) for th in thetas], axis=0)

    def screen_sums(self, d, thetas: list, model, r: np.ndarray, blocks):
        """Screening sums ``(a, H)`` of all ``thetas`` at once, (K, J, k) and (K, J, k, k)
        as :func:`servo.diagnose.select.screen_stats` of :meth:`screen_batch`, computed
        without the columns (a compiled kernel); None: not available, the caller builds
        the columns in chunks."""
        return None

    def grid(self, d, model) -> list:
        return [{}]

    def screen_target(self, d, model, theta: dict) -> np.ndarray | None:
        """An input term's target rows (m,) tried on top of ``model`` (which lacks the
        term), computed faster than the exact chain; None: use the exact chain."""
        return None

    def bounds(self, d, model) -> dict:
        """Refinement bounds per theta: name -> (lo, hi, log_scale)."""
        return {}

    def eligible(self, model) -> str | None:
        """None when the term may be tried on top of ``model``, else why not."""
        if model.has_free(self.name) or (model.has(self.name) and self.thetas):
            return "already in the model"
        for r in self.requires:
            if not model.has(r):
                return f"needs {r} in the model first"
        return None

    def physical(self, theta: dict, coef) -> dict:
        """Reported parameters (name -> value)."""
        return {**dict(zip(self.coefs, map(float, coef))), **{k: float(v) for k, v in theta.items()}}

    def from_physical(self, p: dict) -> tuple[dict, tuple]:
        return {k: p[k] for k in self.thetas}, tuple(p[k] for k in self.coefs)

    def note(self, params: dict) -> str:
        """A remark when a fitted parameter has a sign the physics does not expect."""
        for k, v in params.items():
            if k in self.POSITIVE and v < 0:
                return f"{k} < 0: {self.POSITIVE[k]}"
        return ""

    POSITIVE: dict = {}

    def implausible(self, params: dict) -> str:
        """Why fitted parameters (:meth:`physical`) do not describe this physics ("" if
        they do): then the term is not named, whatever the test said."""
        return ""

    def unit(self, name: str, force_unit: str) -> str:
        return self.units.get(name, "-").replace("F", force_unit)

    def std_extra(self, params: dict, std: dict) -> dict:
        """Std of the derived reported parameters (``std`` holds the fitted ones')."""
        return {}

    # ---- the simulated drive (servo.config.DriveConfig) ----------------------------
    #: its ``[drive]`` fields when a model lacks the term
    absent: dict = {}

    def to_drive(self, P: dict, fit) -> dict:
        """Its ``[drive]`` fields (force unit, m, s) in a fitted model: ``P`` is
        ``fit.combined()`` (every term's reported parameters), ``fit`` the
        :class:`~servo.diagnose.fit.Fit`."""
        return {}

    def from_drive(self, d) -> list:
        """The term as a simulated drive ``d`` (``DriveConfig``) has it: ``(theta, coef)``
        pairs (fixed coefficients), ``[]`` when the drive lacks it."""
        return []

    # ---- the concealed-effect study ------------------------------------------------
    effect: Effect | None = None

    def conceal(self, size: float) -> dict:
        """The ``[drive]`` fields that put this term into the null drive at ``size``."""
        raise NotImplementedError


def _geom(lo: float, hi: float, per_decade: float) -> np.ndarray:
    if not (hi > lo > 0):
        return np.zeros(0)
    k = max(2, int(math.ceil(math.log10(hi / lo) * per_decade)) + 1)
    return np.geomspace(lo, hi, k)


def _c(z) -> np.ndarray:
    return np.ascontiguousarray(z, dtype=float)


def _fold_ranges(blocks) -> tuple[np.ndarray, np.ndarray]:
    """Each fold's first and past-the-end row (K,), int64."""
    starts = np.array([sl.start for sl in blocks.slices], dtype=np.int64)
    stops = np.array([sl.stop for sl in blocks.slices], dtype=np.int64)
    return starts, stops


def _valid_speed(d) -> np.ndarray:
    s = d.sig
    m = d.train_valid if getattr(d, "train_valid", None) is not None else s.valid
    return np.abs(s.v_rows[m])


# ------------------------------------------------------------------ rigid-body terms
class _OneField(Physics):
    """A term that is one coefficient and one ``[drive]`` field of the same name
    (``coefs[0]``): its drive mapping and its concealed effect are that field."""

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        cls.absent = {cls.coefs[0]: 0.0}

    def to_drive(self, P, fit):
        return {self.coefs[0]: P[self.name][self.coefs[0]]}

    def from_drive(self, d):
        return [({}, (getattr(d, self.coefs[0]),))]

    def conceal(self, size):
        return {self.coefs[0]: size}


class Inertia(_OneField):
    name, coefs, units = "inertia", ("J",), {"J": "F*s^2/m"}
    doc = "inertia J*x''"

    def full(self, d, theta, u_eff):
        return d.sig.af


class Viscous(_OneField):
    name, coefs, units = "viscous_friction", ("B",), {"B": "F*s/m"}
    effect = Effect("viscous_friction", "A*s/m", "B", (1e-5, 2e-5, 5e-5, 1e-4, 2e-4), 5e-3, baseline="J,Fc,K,h0",
                    fixed={"B": 0.0})  # fmt: skip
    doc = "viscous friction B*x'"
    POSITIVE = {"B": "the force grows against the motion: negative damping, not friction"}

    def full(self, d, theta, u_eff):
        return d.sig.vf


class Coulomb(Physics):
    name, coefs, units = "coulomb_friction", ("Fc",), {"Fc": "F"}
    absent = {"Fc": 0.0, "Fs": 0.0}
    effect = Effect("coulomb_friction", "A", "Fc = Fs (Coulomb level)", (1e-6, 2e-6, 5e-6, 1e-5, 2e-5), 2e-4,
                    baseline="J,B,K,h0", fixed={"Fc": 0.0, "Fs": 0.0})  # fmt: skip

    def to_drive(self, P, fit):
        Fc = P[self.name]["Fc"]
        return {"Fc": Fc, "Fs": Fc}  # exact sticking; a Stribeck term raises Fs

    def from_drive(self, d):
        return [({}, (d.Fc if d.Fs > 0 else 0.0,))]

    def conceal(self, size):
        return {"Fc": size, "Fs": size}
    doc = "Coulomb friction Fc*sgn(x')"
    POSITIVE = {"Fc": "a force pushing along the motion: not friction"}

    def full(self, d, theta, u_eff):
        return d.sig.sign_v  # the sign the rows see: its switch placed between samples


class Stiffness(_OneField):
    name, coefs, units = "stiffness", ("K",), {"K": "F/m"}
    effect = Effect("stiffness", "A/m", "K", (2e-3, 5e-3, 1e-2, 2e-2, 5e-2), 0.2, baseline="J,B,Fc,h0", fixed={"K": 0.0})
    doc = "stiffness K*x (flex-cable bias, pivot's average slope)"

    def full(self, d, theta, u_eff):
        return d.sig.xf


class Offset(_OneField):
    name, coefs, units = "offset", ("h0",), {"h0": "F"}
    effect = Effect("offset", "A", "h0", (5e-6, 1e-5, 2e-5, 5e-5, 1e-4), 3e-4, baseline="J,B,Fc,K", fixed={"h0": 0.0})
    doc = "constant force h0"

    def full(self, d, theta, u_eff):
        return np.ones(d.sig.n)  # through the rows' filter too: its DC gain is 0.989, not 1


# ------------------------------------------------------------------ friction refinements
class Asymmetric(Physics):
    name, coefs, units = "asymmetric_friction", ("dB",), {"dB": "F*s/m", "b_asymmetry": "-"}
    doc = ("direction-dependent friction: B(+-) = B +- dB.  A direction-dependent Coulomb level "
           "Fc(+-) = Fc +- dFc adds dFc to every sliding row: it is an offset while the arm slides "
           "and is reported in the offset")  # fmt: skip
    requires = ("viscous_friction", "coulomb_friction", "offset")

    effect = Effect("asymmetric_friction", "-", "fc_asymmetry = b_asymmetry", (0.01, 0.02, 0.05, 0.1, 0.2), 0.5)

    def to_drive(self, P, fit):
        B = P.get("viscous_friction", {}).get("B", 0.0)
        return {"b_asymmetry": P[self.name]["dB"] / B} if B else {}

    def from_drive(self, d):
        return [({}, (d.B * d.b_asymmetry,))] if d.b_asymmetry else []

    def conceal(self, size):
        return {"b_asymmetry": size, "fc_asymmetry": size}
    def full(self, d, theta, u_eff):
        return np.abs(d.sig.vf)


class Stribeck(Physics):
    name, coefs, thetas = "stribeck_friction", ("dFs",), ("stribeck_velocity",)
    units = {"dFs": "F", "stribeck_velocity": "m/s", "Fs": "F"}  # Fs: a breakaway found at rest (breakaway.py)
    doc = "Stribeck friction (Fs - Fc)*exp(-(x'/vs)^2)*sgn(x'): higher friction at low speed"
    requires = ("coulomb_friction",)

    effect = Effect("stribeck_friction", "A", "Fs - Fc (Stribeck velocity 2 mm/s)",
                    (2e-5, 5e-5, 1e-4, 2e-4, 5e-4), 5e-4, fixed={"Fc": 1e-3, "stribeck_velocity": 2e-3})  # fmt: skip

    def to_drive(self, P, fit):
        p = P[self.name]
        return {"Fs": P.get("coulomb_friction", {}).get("Fc", 0.0) + p["dFs"], "stribeck_velocity": p["stribeck_velocity"]}

    def from_drive(self, d):
        if d.Fs > d.Fc and d.Fs > 0:
            return [({"stribeck_velocity": d.stribeck_velocity}, (d.Fs - d.Fc,))]
        return []

    def conceal(self, size):
        return {"Fs": self.effect.fixed["Fc"] + size}
    def implausible(self, params: dict) -> str:
        if params["dFs"] < 0:
            return (f"the best fit has dFs = {params['dFs']:.3g} < 0: friction lower at low speed than sliding, a "
                    "smooth (pre-sliding-like) rise, the opposite of a Stribeck peak")  # fmt: skip
        return ""

    def full(self, d, theta, u_eff):
        v = d.sig.vf
        return d.sig.sign_v * np.exp(-((v / theta["stribeck_velocity"]) ** 2))

    def _range(self, d):
        v = _valid_speed(d)
        return max(2.0 * d.sig.v_threshold, float(np.quantile(v, 0.02))), float(np.quantile(v, 0.75))

    def grid(self, d, model):
        return [{"stribeck_velocity": float(v)} for v in _geom(*self._range(d), 5)]

    def bounds(self, d, model):
        return {"stribeck_velocity": (*self._range(d), True)}


class Hysteresis(Physics):
    name, coefs, thetas = "hysteresis", ("Ha",), ("dahl_length",)
    units = {"Ha": "F", "dahl_length": "m", "sigma": "F/m"}
    doc = ("Dahl hysteresis (paper eq. 6-7): a hidden force with turnaround memory, slope sigma at a "
           "reversal, asymptote +-Ha, Dahl length Ha/sigma")  # fmt: skip
    requires = ("coulomb_friction",)

    #: no Dahl element: a negligible one (1e-12 A over a Dahl length of 1 m)
    absent = {"Ha": 1e-12, "sigma": 1e-12}
    effect = Effect("hysteresis", "A", "Dahl Ha (Dahl length 3 um)", (1e-5, 2e-5, 5e-5, 1e-4, 2e-4), 1e-3)

    def to_drive(self, P, fit):
        p = P[self.name]
        if not p["Ha"] > 0:
            return dict(self.absent)
        return {"Ha": p["Ha"], "sigma": p["sigma"], "alpha": fit.model.get(self.name).params.get("alpha", 1.0)}

    def from_drive(self, d):
        if d.Ha > 1e-6 * max(abs(d.h0), d.Fc, 1e-30):  # a written model without hysteresis has Ha = 1e-12
            return [({"dahl_length": d.Ha / d.sigma, "alpha": d.alpha}, (d.Ha,))]
        return []

    def conceal(self, size):
        return {"Ha": size, "sigma": size / 3e-6}

    def std_extra(self, params, std):
        if "Ha" in std and "dahl_length" in std:
            rel = np.hypot(std["Ha"] / params["Ha"] if params["Ha"] else 0, std["dahl_length"] / params["dahl_length"])
            return {"sigma": float(params["sigma"] * rel)}
        return {}
    def implausible(self, params: dict) -> str:
        if params["Ha"] < 0:
            return f"the best fit has Ha = {params['Ha']:.3g} < 0: a force released after a reversal, not a Dahl friction"
        return ""

    def full(self, d, theta, u_eff):
        s = d.sig
        out = np.empty(s.n)
        lam = theta["dahl_length"]
        dahl_trace(s.xf, s.vf, s.v_threshold, 1.0 / lam, 1.0, float(theta.get("alpha", 1.0)), 0.0, out)
        return out

    def _range(self, d):
        s = d.sig
        span = float(np.ptp(s.xf))
        return max(10.0 * s.noise_x, 1e-6 * span), 0.1 * span

    def grid(self, d, model):
        return [{"dahl_length": float(v)} for v in _geom(*self._range(d), 3)]

    def bounds(self, d, model):
        return {"dahl_length": (*self._range(d), True)}

    def physical(self, theta, coef):
        p = super().physical(theta, coef)
        p["sigma"] = p["Ha"] / theta["dahl_length"]
        return p


# ------------------------------------------------------------------ structure
class Resonance(Physics):
    name, coefs, thetas = "resonance", ("gain",), ("frequency_hz", "zeta")
    units = {"gain": "-", "frequency_hz": "Hz", "zeta": "-"}
    doc = ("a lightly damped mode in the measured position, x_meas = x + gain*q with "
           "q'' + 2*zeta*w*q' + w^2*q = u/J: in the force balance, -gain*s^2/(s^2 + 2*zeta*w*s + w^2) u")  # fmt: skip
    uses_input = True
    screening = True
    ZETAS = (0.005, 0.02, 0.06)
    ZETA_MAX = 0.1  # a lightly damped mode
    MAX_MODES = 4

    absent = {"mode_hz": [], "mode_zeta": [], "mode_gain": []}
    effect = Effect("resonance", "-", "modal gain of a 700 Hz, zeta 0.02 mode", (2e-4, 5e-4, 1e-3, 2e-3, 5e-3), 0.05)

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

    def conceal(self, size):
        return {"mode_hz": [700.0], "mode_zeta": [0.02], "mode_gain": [size]}
    def eligible(self, model):
        n = sum(t.physics == self.name for t in model.terms)
        return None if n < self.MAX_MODES else f"{n} modes already in the model"

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
        s = d.sig
        b, a = self.biquad(theta["frequency_hz"], theta["zeta"], 1.0 / s.dt)
        return -signal.lfilter(b, a, s.force(u_eff))

    def screen(self, d, theta, model):
        y = d.target_raw(model)
        b, a = self.biquad(theta["frequency_hz"], theta["zeta"], 1.0 / d.sig.row_dt)
        return -signal.lfilter(b, a, y)[:, None]

    def screen_sums(self, d, thetas, model, r, blocks):
        """All variants' biquads run over the force rows together (:func:`kernels.screen.biquad_stats`)."""
        fs = 1.0 / d.sig.row_dt
        BA = [self.biquad(th["frequency_hz"], th["zeta"], fs) for th in thetas]
        B = np.ascontiguousarray(np.array([b for b, _ in BA], dtype=float).T)  # (3, J)
        A = np.ascontiguousarray(np.array([a for _, a in BA], dtype=float).T)
        starts, stops = _fold_ranges(blocks)
        K, J = starts.size, len(thetas)
        a, H = np.empty((K, J, 1)), np.empty((K, J, 1, 1))
        y = np.ascontiguousarray(d.target_raw(model), dtype=float)
        biquad_stats(y, _c(r), _c(blocks.weights), starts, stops, B, A, -1.0, a, H)
        return a, H

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

    def implausible(self, params: dict) -> str:
        if params["zeta"] >= 0.95 * self.ZETA_MAX:
            return (f"the best mode sits at the damping bound (zeta {params['zeta']:.3g}): what the data show is not a "
                    "lightly damped mode (a delay or a filter acts like a heavily damped one)")  # fmt: skip
        return ""


class TimeDelay(Physics):
    name, kind, thetas, units = "time_delay", "input", ("delay_s",), {"delay_s": "s"}
    doc = "the input reaches the arm delay_s later than recorded (negative: the log lags the motion)"

    absent = {"input_delay_s": 0.0}
    effect = Effect("time_delay", "s", "input delay", (1e-6, 2e-6, 3e-6, 5e-6, 1e-5), 2e-5)

    def to_drive(self, P, fit):
        return {"input_delay_s": P[self.name]["delay_s"]}

    def from_drive(self, d):
        return [({"delay_s": d.input_delay_s}, ())] if d.input_delay_s > 0 else []

    def conceal(self, size):
        return {"input_delay_s": size}
    @staticmethod
    def transform(u, theta, dt):
        k = np.arange(u.size, dtype=float)
        return np.interp(k - theta["delay_s"] / dt, k, u)

    def _range(self, d):
        q = d.sig.settings.decimate
        return -q * d.sig.dt, 2 * q * d.sig.dt

    def grid(self, d, model):
        """Tenths of a sample up to half a sample, quarter samples up to two either way,
        whole samples beyond (a 0.1-sample delay on a lead-lag loop was missed with
        quarter samples alone: 17/20 of the proving ground's delays, 20/20 with tenths)."""
        q = d.sig.settings.decimate
        steps = sorted({j / 10 for j in range(-5, 6)} | {j / 4 for j in range(-8, 9)} | set(range(-q, 2 * q + 1)) - {0})
        return [{"delay_s": j * d.sig.dt} for j in steps]

    def bounds(self, d, model):
        return {"delay_s": (*self._range(d), False)}


class Saturation(Physics):
    name, kind, thetas, units = "input_saturation", "input", ("level",), {"level": "F"}
    doc = "the input is clipped at +-level before it reaches the arm (amplifier current limit)"
    QUANTILES = (0.9, 0.95, 0.97, 0.98, 0.99, 0.995, 0.998)
    MIN_CLIPPED = 10  # samples

    # without a saturation the model has no limit: the config's largest magnitude (its
    # default, 1 A, would clip a recording in N when the file is held against it)
    absent = {"current_limit": MAGNITUDE_MAX}
    effect = Effect("input_saturation", "-", "fraction of the samples clipped", (0.002, 0.005, 0.01, 0.02, 0.05), 0.05)

    def to_drive(self, P, fit):
        return {"current_limit": P[self.name]["level"]}

    def from_drive(self, d):
        return [({"level": d.current_limit}, ())]

    def conceal(self, size):
        return {}  # the level that clips a fraction `size`: set from a first run (concealed_recording)
    @staticmethod
    def transform(u, theta, dt):
        return np.clip(u, -theta["level"], theta["level"])

    def _levels(self, d):
        au = np.abs(d.sig.u[d.train_samples])
        lv = np.unique(np.quantile(au, self.QUANTILES))
        return [float(L) for L in lv if np.count_nonzero(au > L) >= self.MIN_CLIPPED and L > 0]

    def grid(self, d, model):
        return [{"level": L} for L in self._levels(d)]

    def bounds(self, d, model):
        lv = self._levels(d)
        au = np.abs(d.sig.u[d.train_samples])
        return {"level": (lv[0] if lv else 0.0, float(np.quantile(au, 0.999)), False)}


class PositionGain(Physics):
    name, coefs = "position_dependent_gain", ("kf_linear", "kf_quadratic")
    units = {"kf_linear": "1/m", "kf_quadratic": "1/m^2"}
    doc = "force constant varying over the stroke: the arm gets kf(x)*u, kf = 1 + kf_linear*x + kf_quadratic*x^2"
    uses_input = True

    STROKE = 0.015  # m: the drive's kf fields are the changes at this stroke
    effect = Effect("position_dependent_gain", "-", "kf_linear (force-constant change at +15 mm)",
                    (0.02, 0.05, 0.1, 0.2, 0.5), 0.5)  # fmt: skip

    def to_drive(self, P, fit):
        g, s = P[self.name], self.STROKE
        return {"kf_linear": g["kf_linear"] * s, "kf_quadratic": g["kf_quadratic"] * s**2, "stroke": s}

    def from_drive(self, d):
        if d.kf_linear or d.kf_quadratic:
            return [({}, (d.kf_linear / d.stroke, d.kf_quadratic / d.stroke**2))]
        return []

    def conceal(self, size):
        return {"kf_linear": size}
    def full(self, d, theta, u_eff):
        ua = d.sig.force(u_eff)
        x = d.sig.xf
        return np.column_stack([-x * ua, -x * x * ua])


class Cogging(Physics):
    name, coefs, thetas = "cogging", ("a_sin", "a_cos"), ("period",)
    units = {"a_sin": "F", "a_cos": "F", "period": "m", "amplitude": "F", "phase": "rad"}
    doc = "a force periodic in position: amplitude*sin(2*pi*x/period + phase)"
    screening = True
    MAX_GRID = 3000

    effect = Effect("cogging", "A", "cogging amplitude (period 50 um)", (1e-6, 2e-6, 5e-6, 1e-5, 2e-5), 1e-4)

    def to_drive(self, P, fit):
        c = P[self.name]
        return {"cogging": c["amplitude"], "cogging_period": c["period"], "cogging_phase": c["phase"]}

    def from_drive(self, d):
        if not d.cogging:
            return []
        theta, coef = self.from_physical({"amplitude": d.cogging, "period": d.cogging_period, "phase": d.cogging_phase})
        return [(theta, coef)]

    def conceal(self, size):
        return {"cogging": size, "cogging_period": 50e-6}

    def std_extra(self, params, std):
        if "a_sin" in std and "a_cos" in std:
            return {"amplitude": float(np.hypot(std["a_sin"], std["a_cos"]) / np.sqrt(2))}
        return {}
    def full(self, d, theta, u_eff):
        w = 2 * math.pi * d.sig.xf / theta["period"]
        return np.column_stack([np.sin(w), np.cos(w)])

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
        starts, stops = _fold_ranges(blocks)
        K, J = starts.size, k.size
        a, H = np.empty((K, J, 2)), np.empty((K, J, 2, 2))
        dk = (k[-1] - k[0]) / (J - 1)
        cogging_stats(_c(d.sig.x_rows), _c(r), _c(blocks.weights), starts, stops, float(k[0]), float(dk), a, H)
        return a, H

    def _k_range(self, d):
        s = d.sig
        span = float(np.ptp(s.x_rows[d.train_rows]))
        v25 = float(np.quantile(_valid_speed(d), 0.25))
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


class Quantization(Physics):
    name, kind, thetas, units = "quantization", "sensor", ("step",), {"step": "m", "offset": "m"}
    doc = "position sensor quantised to a lattice of step `step` (an encoder's count)"

    absent = {"position_quantum": 0.0}  # a found lattice is a finding, not a fitted term
    effect = Effect("quantization", "m", "position quantum", (5e-9, 1e-8, 2e-8, 5e-8, 1e-7), 5e-8)

    def conceal(self, size):
        return {"position_quantum": size}
    def eligible(self, model):
        return "a sensor effect: tested on its own (servo.diagnose.quantization)"


VOCABULARY = {
    c.name: c()
    for c in (Inertia, Viscous, Coulomb, Stiffness, Offset, Asymmetric, Stribeck, Hysteresis, Resonance, TimeDelay,
              Saturation, PositionGain, Cogging, Quantization)  # fmt: skip
}


def register(cls) -> None:
    """Add a term defined in a module of its own to :data:`VOCABULARY` (that module's
    one registration line; the package imports it, :mod:`servo.diagnose`)."""
    VOCABULARY[cls.name] = cls()


#: the baseline terms of eq. (3) and the vocabulary term each is
BASELINE_TERMS = {"J": "inertia", "B": "viscous_friction", "Fc": "coulomb_friction", "K": "stiffness", "h0": "offset"}

__all__ = ["BASELINE_TERMS", "NAMES", "VOCABULARY", "Effect", "Physics", "register"]

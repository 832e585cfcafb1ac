"""Recordings of the proving ground: families, controllers, excitations, rates.

:func:`recording` makes one recording from a :class:`Case` and a seed with the
independent integrator of :mod:`studies.proving.integrate` and returns it with
its truth (what a diagnosis should name, the verdict it should reach).

**Scale.**  The plant's time scales follow the sample rate: the motion lives around
``f_m = fs/2000`` (25 Hz at 50 kHz, 0.25 Hz at 500 Hz), the closed loop crosses over at
``fs/50``, the stroke is 1 mm.  So a rate is a label on the same dimensionless problem
except where a case sets something in samples or in the rows' band (a mode's frequency
relative to the band edge ``0.035*fs``, a delay in samples, a sensor cutoff relative to
``fs``); the seeds vary amplitudes, phases and the plant's parameters by +-30 %.

**Null physics** (nothing the paper's baseline ``J, B, Fc, K, h0`` lacks): a rigid body,
viscous friction, Karnopp Coulomb friction with ``Fs = Fc``, a spring and an offset;
sensor white noise of 1e-6 of the stroke.

**Families** (:data:`FAMILIES`; ``size`` is relative, see each entry's ``what``) and the
vocabulary term each should be named as (Bouc-Wen, LuGre pre-sliding and Maxwell-slip
are ``hysteresis``; Stribeck curves of any shape and Karnopp breakaway are
``stribeck_friction``; a sensor low-pass is ``sensor_lag``, or ``time_delay`` where the
rows cannot tell the two apart: :func:`accepted`).  Partial-in-time
cases: ``saturation_late`` (the amplifier clips only in the last 30 %, which the
training part never sees: the verdict must be ``unexplained`` with a train/test gap) and
``hysteresis_late`` (a LuGre element appearing half-way).  ``out_of_scope``: the
position of another run (another kind of excitation, so no frequency lines shared with
the input), unrelated to the recorded input.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

import studies.proving.integrate as ig
from servo.io.recording import Recording

RATES = (500.0, 1000.0, 5000.0, 20000.0, 50000.0)
CONTROLLERS = ("pdi", "leadlag", "open")
EXCITATIONS = ("seeks", "multisine", "chirp", "prbs", "pulses")
STROKE = 1e-3
NOISE = 1e-6  # of the stroke


@dataclass(frozen=True)
class Family:
    """An effect family: the ``name`` a diagnosis should give (None: none), what its
    size is, the sizes of the study, and the verdict a clear case should get."""

    expect: str | None
    what: str
    sizes: tuple
    verdict: tuple = ("explained",)
    #: other names accepted, in words (the rule is :func:`accepted`)
    also: str = ""


FAMILIES = {
    "null": Family(None, "-", (0.0,), ("consistent",)),
    "lugre": Family("hysteresis", "LuGre element level / Fc (bristle length 0.3 % of the stroke)", (0.05, 0.1, 0.2, 0.5)),
    "bouc_wen": Family("hysteresis", "Bouc-Wen level / Fc (n = 1, beta/gamma 0.7/0.3, length 0.3 % of the stroke)",
                       (0.05, 0.1, 0.2, 0.5)),
    "maxwell_slip": Family("hysteresis", "Maxwell-slip total level / Fc (4 elements, 0.1-1.2 % of the stroke)",
                           (0.05, 0.1, 0.2, 0.5)),
    "stribeck_exp": Family("stribeck_friction", "(Fs - Fc)/Fc, exponential shape", (0.1, 0.2, 0.5, 1.0)),
    "stribeck_lorentz": Family("stribeck_friction", "(Fs - Fc)/Fc, Lorentzian shape", (0.1, 0.2, 0.5, 1.0)),
    "stribeck_power": Family("stribeck_friction", "(Fs - Fc)/Fc, exp(-r^0.6) shape", (0.1, 0.2, 0.5, 1.0)),
    "karnopp": Family("stribeck_friction", "(Fs - Fc)/Fc, breakaway only (vs 0.2 % of the speed scale)",
                      (0.2, 0.5, 1.0, 2.0)),
    "mode_in_band": Family("resonance", "modal gain of a mode at 0.3 x the rows' band edge", (1e-3, 3e-3, 1e-2, 3e-2)),
    "mode_above_band": Family("resonance", "modal gain of a mode at 2 x the rows' band edge", (1e-3, 3e-3, 1e-2, 3e-2),
                              ("explained", "unexplained")),
    "delay": Family("time_delay", "input delay, samples", (0.1, 0.25, 0.5, 1.0)),
    "sensor_lowpass": Family("sensor_lag", "fs / sensor cutoff", (2.0, 5.0, 10.0, 20.0),
                             also="or time_delay where w_e*tau <= 0.3"),
    "quantization": Family("quantization", "quantum / noise std", (5.0, 10.0, 30.0, 100.0)),
    "saturation_late": Family(None, "fraction of the last 30 % clipped", (0.05, 0.1, 0.2), ("unexplained",)),
    "hysteresis_late": Family("hysteresis", "LuGre level / Fc, present in the second half only", (0.2, 0.5),
                              ("explained", "unexplained")),
    "out_of_scope": Family(None, "-", (0.0,), ("out_of_scope",)),
}


#: a sensor lag of ``tau`` samples is scored as a delay too where ``w_e*tau`` is at most
#: this, ``w_e = 2*pi*0.4/q`` the rows' band edge (rad/sample): a delay of ``tau`` then
#: leaves at most ``(w_e*tau)^2/2`` = 4.5 % of the force at the band edge unexplained
LAG_AS_DELAY = 0.3


def lag_samples(size: float) -> float:
    """The time constant (samples) of the ``sensor_lowpass`` family at ``size`` (fs/cutoff)."""
    return size / (2 * np.pi)


def accepted(family: str, size: float, decimate: int | None) -> tuple:
    """The vocabulary names that count as a detection of ``family`` at ``size`` on a
    recording whose rows are decimated by ``decimate`` (None: unknown, the default 10).

    The rule, fixed before any scoring: a family's ``expect``; for ``sensor_lowpass``
    also ``time_delay`` where the lag and a delay are the same physics to the rows,
    ``w_e*tau <= LAG_AS_DELAY`` (``tau`` the lag in samples, ``w_e = 2*pi*0.4/q`` the
    rows' band edge in rad/sample): a first-order lag and a delay of ``tau`` agree to
    first order in ``w*tau`` and differ by about ``(w*tau)^2/2`` of the force.  At
    ``q = 10`` that accepts a delay for ``fs/2`` and ``fs/5`` (``w_e*tau`` 0.08, 0.2),
    not for ``fs/10`` and ``fs/20`` (0.4, 0.8)."""
    fam = FAMILIES[family]
    if fam.expect is None:
        return ()
    names = (fam.expect,)
    if family == "sensor_lowpass":
        w_e = 2 * np.pi * 0.4 / (decimate or 10)
        if w_e * lag_samples(size) <= LAG_AS_DELAY:
            names += ("time_delay",)
    return names


@dataclass(frozen=True)
class Case:
    """One recording's recipe."""

    family: str = "null"
    size: float = 0.0
    controller: str = "pdi"
    excitation: str = "multisine"
    rate_hz: float = 5000.0
    samples: int = 30000


def _controller(kind: str, J: float, wc: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete (bilinear) controller from the error to the command: PD plus integral
    with a filtered derivative, or lead-lag with an integrating lag; gains for a
    crossover ``wc`` (rad/s) on ``1/(J s^2)``."""
    if kind == "pdi":
        kp, kd, ki, wf = J * wc**2 / 2.0, 1.2 * J * wc, J * wc**3 / 20.0, 5.0 * wc
        # kp + ki/s + kd*s/(1 + s/wf) over the common denominator s*(1 + s/wf)
        num = np.polyadd(np.polyadd(kp * np.array([1 / wf, 1.0, 0.0]), ki * np.array([1 / wf, 1.0])),
                         kd * np.array([1.0, 0.0, 0.0]))  # fmt: skip
        den = np.array([1 / wf, 1.0, 0.0])
    else:
        wz, wp, wl = wc / 3.0, 3.0 * wc, wc / 10.0
        num = np.polymul([1 / wz, 1.0], [1.0, wl])
        den = np.polymul([1 / wp, 1.0], [1.0, 0.0])
        s = 1j * wc
        k = J * wc**2 / abs(np.polyval(num, s) / np.polyval(den, s))
        num = k * num
    b, a = signal.bilinear(num, den, fs)
    return np.ascontiguousarray(b / a[0]), np.ascontiguousarray(a / a[0])


def _smooth_steps(rng, n: int, fs: float, fm: float) -> np.ndarray:
    """Long seek strokes: cosine moves between random targets within the stroke, dwells
    between them (few reversals)."""
    out = np.zeros(n)
    k, x = 0, 0.0
    while k < n:
        target = rng.uniform(-1, 1) * STROKE
        move = int(fs * rng.uniform(0.8, 1.6) / fm)
        dwell = int(fs * rng.uniform(0.2, 0.6) / fm)
        s = 0.5 - 0.5 * np.cos(np.pi * np.arange(move) / move)
        seg = x + (target - x) * s
        out[k : k + move] = seg[: max(0, min(move, n - k))]
        k += move
        out[k : k + dwell] = target
        k += dwell
        x = target
    return out


def _excitation(kind: str, rng, n: int, fs: float, fm: float, F: float) -> tuple[np.ndarray, np.ndarray]:
    """Reference (m) and force excitation (F) of one kind (module doc)."""
    t = np.arange(n) / fs
    fade = np.clip(t * fm / 2.0, 0, 1)
    if kind == "seeks":
        r = _smooth_steps(rng, n, fs, fm)
        w = 0.05 * F * np.sign(rng.standard_normal(n // 8 + 1)).repeat(8)[:n]
    elif kind == "multisine":
        fr = np.geomspace(fm / 10, fm, 5)
        r = sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in fr) * STROKE / 3
        b, a = signal.butter(2, [min(2 * fm / fs, 0.4), min(20 * fm / fs, 0.45)], btype="band")
        w = signal.lfilter(b, a, rng.standard_normal(n))
        w *= 0.1 * F / w.std()
    elif kind == "chirp":
        r = STROKE * signal.chirp(t, fm / 20, t[-1], 2 * fm, method="logarithmic", phi=rng.uniform(0, 360))
        w = 0.05 * F * rng.standard_normal(n)
    elif kind == "prbs":
        r = 0.7 * STROKE * np.sin(2 * np.pi * fm / 5 * t + rng.uniform(0, 2 * np.pi))
        clock = max(1, int(fs / (20 * fm)))
        w = 0.3 * F * np.sign(rng.standard_normal(n // clock + 1)).repeat(clock)[:n]
    elif kind == "pulses":
        r = 0.7 * STROKE * np.sin(2 * np.pi * fm / 5 * t + rng.uniform(0, 2 * np.pi))
        period, width = max(4, int(fs / fm)), max(1, int(fs / (8 * fm)))
        w = np.zeros(n)
        for k0 in range(0, n, period):
            w[k0 : k0 + width] = rng.choice([-1.0, 1.0]) * 0.5 * F
    else:
        raise ValueError(f"unknown excitation {kind!r}")
    return fade * r, fade * w


def _params(case: Case, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    fs = case.rate_hz
    fm = fs / 2000.0
    wm = 2 * np.pi * fm
    var = lambda: rng.uniform(0.7, 1.3)  # noqa: E731
    J = 1e-3 * var()
    F = J * STROKE * wm**2  # the force scale of the motion
    p = np.zeros(ig.N_PARAMS)
    p[ig.P_RATE] = fs
    p[ig.P_J] = J
    p[ig.P_B] = 0.2 * J * wm * var()
    p[ig.P_K] = J * (wm / 5) ** 2 * var()
    p[ig.P_FC] = p[ig.P_FS] = 0.1 * F * var()
    p[ig.P_H0] = 0.2 * p[ig.P_FC] * var()
    p[ig.P_VS] = 0.05 * STROKE * wm
    p[ig.P_NOISE] = NOISE * STROKE * var()
    p[ig.P_NSUB] = 4
    p[ig.P_COG_PERIOD] = 1.0
    mk, md = np.zeros(0), np.zeros(0)
    fam, s = case.family, case.size
    Fc = p[ig.P_FC]
    L = 3e-3 * STROKE
    if fam in ("lugre", "hysteresis_late") and s > 0:  # size 0 (a twin): no element
        p[ig.P_HYST], p[ig.P_HLEVEL] = ig.HYST_LUGRE, s * Fc
        p[ig.P_SIGMA0] = s * Fc / L
        p[ig.P_SIGMA1] = 0.0
    elif fam == "bouc_wen":
        p[ig.P_HYST] = ig.HYST_BOUCWEN
        p[ig.P_BW_A], p[ig.P_BW_BETA], p[ig.P_BW_GAMMA] = 1.0, 0.7 / L, 0.3 / L
        p[ig.P_BW_K] = s * Fc / L
    elif fam == "maxwell_slip":
        p[ig.P_HYST] = ig.HYST_MAXWELL
        md = L * np.array([0.3, 1.0, 2.0, 4.0])
        mk = 0.25 * s * Fc / md
    elif fam.startswith("stribeck") or fam == "karnopp":
        p[ig.P_FS] = Fc * (1 + s)
        p[ig.P_SHAPE] = {"stribeck_exp": ig.SHAPE_EXP, "stribeck_lorentz": ig.SHAPE_LORENTZ,
                         "stribeck_power": ig.SHAPE_POWER, "karnopp": ig.SHAPE_EXP}[fam]  # fmt: skip
        p[ig.P_DELTA] = 0.6
        if fam == "karnopp":
            p[ig.P_VS] = 0.002 * STROKE * wm
    elif fam in ("mode_in_band", "mode_above_band"):
        edge = 0.035 * fs
        p[ig.P_MODE_HZ] = (0.3 if fam == "mode_in_band" else 2.0) * edge
        p[ig.P_MODE_ZETA], p[ig.P_MODE_GAIN] = 0.02, s
    elif fam == "delay":
        p[ig.P_DELAY] = s / fs
    elif fam == "sensor_lowpass":
        p[ig.P_SENSOR_HZ] = fs / s if s > 0 else 0.0  # size 0 (a twin): no low-pass
    elif fam == "quantization":
        p[ig.P_QUANTUM] = s * p[ig.P_NOISE]
    p[ig.P_DV] = 1e-3 * p[ig.P_NOISE] * fs
    info = {"J": J, "B": p[ig.P_B], "K": p[ig.P_K], "Fc": Fc, "Fs": p[ig.P_FS], "h0": p[ig.P_H0], "F_scale": F,
            "fm_hz": fm}  # fmt: skip
    return p, mk, md, info


def _simulate(case: Case, seed: int, u_max_late: float | None = None):
    rng = np.random.default_rng(seed)
    p, mk, md, info = _params(case, rng)
    fs, n = case.rate_hz, case.samples
    r, w = _excitation(case.excitation, rng, n, fs, info["fm_hz"], info["F_scale"])
    noise = rng.standard_normal(n)
    if case.controller == "open":
        # feedforward of the reference through the nominal rigid model, plus the excitation
        a = np.gradient(np.gradient(r, 1 / fs), 1 / fs)
        vr = np.gradient(r, 1 / fs)
        w = p[ig.P_J] * a + p[ig.P_B] * vr + p[ig.P_K] * r + p[ig.P_H0] + p[ig.P_FC] * np.tanh(vr / p[ig.P_VS]) + w
        b, a_ = np.zeros(1), np.ones(1)
        p[ig.P_CLOSED] = 0.0
    else:
        b, a_ = _controller(case.controller, p[ig.P_J], 2 * np.pi * fs / 50, fs)
        p[ig.P_CLOSED] = 1.0
    u_max = np.full(n, 1e30)
    if u_max_late is not None:
        u_max[int(0.7 * n) :] = u_max_late
    gate = np.ones(n)
    if case.family == "hysteresis_late":
        gate[: n // 2] = 0.0
    u, y, x = np.zeros(n), np.zeros(n), np.zeros(n)
    ig.run(p, np.ascontiguousarray(r), np.ascontiguousarray(w), u_max, gate, noise, b, a_,
           np.ascontiguousarray(mk), np.ascontiguousarray(md), u, y, x, n)  # fmt: skip
    return u, y, x, info, w


def recording(case: Case, seed: int = 0, excitation: bool = False) -> tuple[Recording, dict]:
    """One recording of ``case`` (module doc) and its truth: ``expect`` (the vocabulary
    term a diagnosis should name, None for none), ``verdicts`` (the right verdicts),
    the plant's parameters.  With ``excitation``, a closed loop's recording carries the
    force excitation injected at the plant's input as its ``r`` (what a lab records for
    a closed-loop frequency response; the diagnosis's instrument,
    :mod:`servo.diagnose.frf_modes`); an open loop's never does (its whole input is
    exogenous)."""
    if case.family not in FAMILIES:
        raise ValueError(f"unknown family {case.family!r}")
    fam = FAMILIES[case.family]
    lim = None
    if case.family == "saturation_late":  # the level that clips a fraction `size` of the last 30 %
        u, *_ = _simulate(case, seed)
        lim = float(np.quantile(np.abs(u[int(0.7 * case.samples) :]), 1.0 - case.size))
    u, y, x, info, w = _simulate(case, seed, lim)
    if case.family == "out_of_scope":  # the position of an unrelated run
        other = "seeks" if case.excitation != "seeks" else "chirp"  # no frequency lines shared with the input
        _, y, x, *_ = _simulate(Case("null", 0.0, case.controller, other, case.rate_hz, case.samples), seed + 7919)
    t = np.arange(case.samples) / case.rate_hz
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
        raise FloatingPointError(f"proving ground: {case} seed {seed} diverged")
    truth = {"family": case.family, "size": case.size, "expect": fam.expect, "verdicts": list(fam.verdict),
             "case": case.__dict__, "seed": seed, **info}  # fmt: skip
    if lim is not None:
        truth["u_max_late"] = lim
    ref = w.copy() if excitation and case.controller != "open" else None
    rec = Recording(t, u, y, None, source=f"proving:{case.family}:{case.size:g}:{case.controller}:{case.excitation}:"
                    f"{case.rate_hz:g}Hz:seed{seed}", meta={"truth": truth}, r=ref)  # fmt: skip
    return rec, truth


__all__ = ["CONTROLLERS", "Case", "EXCITATIONS", "FAMILIES", "RATES", "accepted", "recording"]

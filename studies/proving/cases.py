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
``Case.motion_hz`` sets ``f_m`` instead (the plant's time scales follow it, the loop's
crossover stays at ``fs/50``): a fast motion at a low rate, a reversal every few samples
(a hysteretic benchmark at 750 Hz driven at 5-150 Hz).

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

**The second set of kinds** (issue 24), options that leave every recording of the
first set as it was (the same arrays to the bit: the seeds' draws, :data:`CONTROLLERS`,
:data:`EXCITATIONS` and so the study's combinations are unchanged):

* ``controller="force"``: an open-loop drive with no controller at all: the input is
  a holding bias (the nominal offset ``h0``) plus the excitation as a force, and the
  spring is 25 times stiffer (natural frequency ``f_m``, so that the dry friction's
  sticking band is a tenth of the stroke); the excitation's level is set so that the
  linear spring-mass model's response peaks at 0.7 of the stroke.  ``"open"``
  (feedforward of a reference through the nominal rigid model) stays beside it.
* ``excitation="steps"``: a reference of steps between random targets in the stroke,
  held 0.05-0.15 motion periods (a closed loop settles in a few per cent of one, so
  the arm is at rest most of a longer hold), with the seeks' small random force (a
  sign held 8 samples, 5 % of the force scale); smoothed by a second-order filter at
  ``5*f_m`` for the ``open`` feedforward.  For ``force``, force steps held 0.3-0.8
  motion periods.  ``force`` takes :data:`FORCE_EXCITATIONS`: ``multisine`` (8 tones
  ``f_m/10``-``3*f_m``), ``prbs`` (clock 3 samples: broadband to about ``fs/3``, what
  reaches modes up to the Nyquist frequency), ``chirp`` (logarithmic ``f_m/20`` to
  ``20*f_m``) and ``steps``.
* ``noise``: ``"white"``, ``"pink"`` (PSD ``1/f`` down to the recording's lowest
  frequency) or ``"lowpass"`` (first-order, corner ``2*f_m``): coloured sensor noise of
  the same standard deviation as the white one, shaped from the same draws
  (:func:`sensor_noise`).
* families ``modes`` (four lightly damped modes from ``0.06*fs`` to ``0.45*fs``, up to
  the Nyquist frequency), ``drift`` (a wandering force offset), ``dead_zone`` (input),
  ``backlash`` (between motor and load), ``cubic_hard`` and ``cubic_soft`` (a cubic
  spring), ``stribeck_gauss`` (Gaussian Stribeck shape) and ``lugre_stribeck`` (a LuGre
  element whose level falls with speed as a Gaussian Stribeck curve: the full LuGre
  friction model's steady state).  A family whose ``expect`` is not (yet) a term of the
  diagnosis's vocabulary (``drift``, ``dead_zone``, ``backlash``, ``cubic_spring``)
  has the expected verdict ``unexplained`` until it is (:func:`expected_verdicts`).
  Their random draws (mode frequencies, the drift's path) come from a generator of
  their own, ``default_rng([seed, 24])``, the same for a recording and its twin.
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
#: the drives without feedback (``force``: no controller at all, module doc)
OPEN = ("open", "force")
#: every excitation (``steps`` is outside :data:`EXCITATIONS`, which the first study's
#: combinations are made of) and the ones the ``force`` drive takes
ALL_EXCITATIONS = EXCITATIONS + ("steps",)
FORCE_EXCITATIONS = ("multisine", "prbs", "chirp", "steps")
NOISES = ("white", "pink", "lowpass")
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
    # the second set (module doc); appended, so that the first families keep their study combinations
    "modes": Family("resonance", "modal gain of each of four modes at 0.06, 0.15, 0.3, 0.45 x fs (-10 %-0, zeta "
                    "0.005-0.03)", (1e-3, 3e-3, 1e-2, 3e-2)),
    "drift": Family("drift", "peak-to-peak of a wandering force offset / Fc (time scale a third of the recording)",
                    (0.1, 0.3, 1.0, 3.0)),
    "dead_zone": Family("dead_zone", "half-width of the input dead zone / Fc", (0.2, 0.5, 1.0, 2.0)),
    "backlash": Family("backlash", "half-gap between motor and load / stroke", (3e-4, 1e-3, 3e-3, 1e-2)),
    "cubic_hard": Family("cubic_spring", "k3*stroke^2/K, hardening", (1.0, 3.0, 10.0, 30.0)),
    "cubic_soft": Family("cubic_spring", "-k3*stroke^2/K, softening (the feedforward `open` loop, whose arm may "
                         "leave the stroke, can run away: the generator then raises)", (0.1, 0.2, 0.3, 0.5)),
    "stribeck_gauss": Family("stribeck_friction", "(Fs - Fc)/Fc, Gaussian shape", (0.1, 0.2, 0.5, 1.0)),
    "lugre_stribeck": Family("stribeck_friction", "(Fs - Fc)/Fc as a LuGre element's level, falling as "
                             "exp(-(v/vs)^2) (bristle length 0.3 % of the stroke)", (0.1, 0.2, 0.5, 1.0),
                             also="or hysteresis (its bristles' pre-sliding)"),
}

#: the families of the second set (module doc)
SECOND = ("modes", "drift", "dead_zone", "backlash", "cubic_hard", "cubic_soft", "stribeck_gauss", "lugre_stribeck")


def in_vocabulary(name: str) -> bool:
    """Whether the diagnosis's vocabulary has a term called ``name`` (read when asked,
    so that a term added later counts)."""
    from servo.diagnose.terms import VOCABULARY

    return name in VOCABULARY


def expected_verdicts(family: str) -> tuple:
    """The right verdicts of a clear case of ``family``: its :class:`Family`'s, except
    that an effect the vocabulary has no term for can only be ``unexplained``."""
    fam = FAMILIES[family]
    if fam.expect is not None and not in_vocabulary(fam.expect):
        return ("unexplained",)
    return fam.verdict


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
    if family == "lugre_stribeck":
        names += ("hysteresis",)
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
    #: sensor noise colour, one of :data:`NOISES`
    noise: str = "white"
    #: the motion's frequency ``f_m`` (Hz); 0: ``fs/2000`` (module doc).  A fast one puts
    #: a reversal every few samples (a benchmark at 750 Hz driven at 5-150 Hz)
    motion_hz: float = 0.0


def sensor_noise(kind: str, white: np.ndarray, fs: float, fm: float) -> np.ndarray:
    """Unit-variance sensor noise (n,) of colour ``kind`` shaped from the white draws
    ``white``: ``white`` itself; ``pink``, PSD proportional to ``1/f`` from the lowest
    frequency of the recording up (no DC); ``lowpass``, a first-order low-pass with
    its corner at ``2*fm`` Hz (flat below, -20 dB/decade above)."""
    if kind == "white":
        return white
    if kind == "pink":
        X = np.fft.rfft(white)
        f = np.fft.rfftfreq(white.size)
        X[0] = 0.0
        X[1:] /= np.sqrt(f[1:] / f[1])
        c = np.fft.irfft(X, white.size)
    elif kind == "lowpass":
        a = np.exp(-2 * np.pi * 2.0 * fm / fs)
        c = signal.lfilter([1.0 - a], [1.0, -a], white)
    else:
        raise ValueError(f"unknown noise {kind!r} (known: {', '.join(NOISES)})")
    return (c - c.mean()) / c.std()


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


def _steps(rng, n: int, fs: float, fm: float, hold: tuple) -> np.ndarray:
    """Steps between random levels in [-1, 1], each held ``hold`` (low, high) motion periods."""
    out = np.zeros(n)
    k = 0
    while k < n:
        hold_k = max(1, int(fs * rng.uniform(*hold) / fm))
        out[k : k + hold_k] = rng.uniform(-1, 1)
        k += hold_k
    return out


def _force_excitation(kind: str, rng, n: int, fs: float, fm: float) -> np.ndarray:
    """The ``force`` drive's excitation of one kind, before its level is set (module doc)."""
    t = np.arange(n) / fs
    if kind == "multisine":
        return sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in np.geomspace(fm / 10, 3 * fm, 8))
    if kind == "prbs":
        return np.sign(rng.standard_normal(n // 3 + 1)).repeat(3)[:n]
    if kind == "chirp":
        return signal.chirp(t, fm / 20, t[-1], 20 * fm, method="logarithmic", phi=rng.uniform(0, 360))
    if kind == "steps":
        return _steps(rng, n, fs, fm, (0.3, 0.8))
    raise ValueError(f"the force drive takes {', '.join(FORCE_EXCITATIONS)}, not {kind!r}")


def _linear_peak(s: np.ndarray, fs: float, J: float, B: float, K: float) -> float:
    """Peak |x| (m) of the linear spring-mass model ``J x'' + B x' + K x = s`` driven
    by ``s`` (F), periodically extended (its steady state, by FFT)."""
    S = np.fft.rfft(s - s.mean())
    w = 2 * np.pi * np.fft.rfftfreq(s.size, 1 / fs)
    return float(np.abs(np.fft.irfft(S / (K - J * w**2 + 1j * B * w), s.size)).max() + abs(s.mean()) / K)


def _excitation(kind: str, rng, n: int, fs: float, fm: float, F: float) -> tuple[np.ndarray, np.ndarray]:
    """Reference (m) and force excitation (F) of one kind (module doc)."""
    t = np.arange(n) / fs
    fade = np.clip(t * fm / 2.0, 0, 1)
    if kind == "steps":
        r = STROKE * _steps(rng, n, fs, fm, (0.05, 0.15))
        w = 0.05 * F * np.sign(rng.standard_normal(n // 8 + 1)).repeat(8)[:n]
    elif kind == "seeks":
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
    fm = case.motion_hz or fs / 2000.0
    wm = 2 * np.pi * fm
    var = lambda: rng.uniform(0.7, 1.3)  # noqa: E731
    J = 1e-3 * var()
    F = J * STROKE * wm**2  # the force scale of the motion
    p = np.zeros(ig.N_PARAMS)
    p[ig.P_RATE] = fs
    p[ig.P_J] = J
    p[ig.P_B] = 0.2 * J * wm * var()
    p[ig.P_K] = J * (wm / 5) ** 2 * var()
    if case.controller == "force":  # no controller: a spring that holds the arm (module doc)
        p[ig.P_K] *= 25.0
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
                         "stribeck_power": ig.SHAPE_POWER, "karnopp": ig.SHAPE_EXP,
                         "stribeck_gauss": ig.SHAPE_GAUSS}[fam]  # fmt: skip
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
    elif fam == "lugre_stribeck" and s > 0:  # size 0 (a twin): no element
        p[ig.P_HYST], p[ig.P_HLEVEL] = ig.HYST_LUGRE, s * Fc
        p[ig.P_SIGMA0], p[ig.P_LG_VS] = s * Fc / L, p[ig.P_VS]
    elif fam == "dead_zone":
        p[ig.P_DEADZONE] = s * Fc
    elif fam == "backlash":
        p[ig.P_BACKLASH] = s * STROKE
    elif fam in ("cubic_hard", "cubic_soft"):
        p[ig.P_K3] = (1.0 if fam == "cubic_hard" else -1.0) * s * p[ig.P_K] / STROKE**2
    p[ig.P_DV] = 1e-3 * p[ig.P_NOISE] * fs
    info = {"J": J, "B": p[ig.P_B], "K": p[ig.P_K], "Fc": Fc, "Fs": p[ig.P_FS], "h0": p[ig.P_H0], "F_scale": F,
            "fm_hz": fm}  # fmt: skip
    return p, mk, md, info


#: the ``modes`` family's modes as fractions of the sample rate (each scaled by 0.9-1.0)
MODE_FRACTIONS = (0.06, 0.15, 0.3, 0.45)


def _second_set(case: Case, seed: int, n: int, fs: float, Fc: float) -> tuple[np.ndarray, np.ndarray, dict]:
    """The force offset (n,) and further modes (m, 3) of the second set's families,
    drawn from their own generator (module doc), and what the truth records of them."""
    rng = np.random.default_rng([seed, 24])
    dist, modes, info = np.zeros(n), np.zeros((0, 3)), {}
    if case.family == "modes":
        hz = np.array(MODE_FRACTIONS) * fs * rng.uniform(0.9, 1.0, len(MODE_FRACTIONS))
        zeta = rng.uniform(0.005, 0.03, len(MODE_FRACTIONS))
        if case.size > 0:
            modes = np.ascontiguousarray(np.column_stack([hz, zeta, np.full(hz.size, case.size)]))
        info = {"modes_hz": hz.tolist(), "modes_zeta": zeta.tolist()}
    elif case.family == "drift":
        # a random walk low-passed at 3/T (time scale a third of the recording), from 0, peak-to-peak size*Fc
        walk = np.cumsum(rng.standard_normal(n))
        walk = signal.sosfiltfilt(signal.butter(2, 3.0 / (n / fs), fs=fs, output="sos"), walk)
        walk -= walk[0]
        if case.size > 0:
            dist = case.size * Fc * walk / np.ptp(walk)
        info = {"drift_pp": float(np.ptp(dist))}
    return dist, modes, info


def _simulate(case: Case, seed: int, u_max_late: float | None = None):
    rng = np.random.default_rng(seed)
    p, mk, md, info = _params(case, rng)
    fs, n = case.rate_hz, case.samples
    fm = info["fm_hz"]
    if case.controller == "force":
        t = np.arange(n) / fs
        sx = _force_excitation(case.excitation, rng, n, fs, fm) * np.clip(t * fm / 2.0, 0, 1)
        level = 0.7 * STROKE / _linear_peak(sx, fs, p[ig.P_J], p[ig.P_B], p[ig.P_K])
        r, w = np.zeros(n), p[ig.P_H0] + level * sx  # the holding bias and the excitation
        info["force_level"] = level
    else:
        r, w = _excitation(case.excitation, rng, n, fs, fm, info["F_scale"])
    noise = sensor_noise(case.noise, rng.standard_normal(n), fs, fm)
    if case.controller == "open":
        if case.excitation == "steps":  # a feedforward cannot follow a step: a smoothed one
            r = signal.sosfiltfilt(signal.butter(2, 5 * fm, fs=fs, output="sos"), r)
        # feedforward of the reference through the nominal rigid model, plus the excitation
        a = np.gradient(np.gradient(r, 1 / fs), 1 / fs)
        vr = np.gradient(r, 1 / fs)
        w = p[ig.P_J] * a + p[ig.P_B] * vr + p[ig.P_K] * r + p[ig.P_H0] + p[ig.P_FC] * np.tanh(vr / p[ig.P_VS]) + w
    if case.controller in OPEN:
        b, a_ = np.zeros(1), np.ones(1)
        p[ig.P_CLOSED] = 0.0
    else:
        b, a_ = _controller(case.controller, p[ig.P_J], 2 * np.pi * fs / 50, fs)
        p[ig.P_CLOSED] = 1.0
    dist, modes, more = _second_set(case, seed, n, fs, p[ig.P_FC])
    info.update(more)
    u_max = np.full(n, 1e30)
    if u_max_late is not None:
        u_max[int(0.7 * n) :] = u_max_late
    gate = np.ones(n)
    if case.family == "hysteresis_late":
        gate[: n // 2] = 0.0
    u, y, x = np.zeros(n), np.zeros(n), np.zeros(n)
    ig.run_full(p, np.ascontiguousarray(r), np.ascontiguousarray(w), u_max, gate, np.ascontiguousarray(noise), b, a_,
                np.ascontiguousarray(mk), np.ascontiguousarray(md), dist, modes, u, y, x, n)  # fmt: skip
    return u, y, x, info, w, {"p": p, "dist": dist, "modes": modes, "noise": noise, "r": r}


def trajectories(case: Case, seed: int = 0) -> dict:
    """The arrays behind one recording of ``case`` (no ``saturation_late`` clip, no
    ``out_of_scope`` swap): ``u``, ``y`` (measured), ``x`` (the motor's true position),
    ``w`` (excitation, F), ``r`` (reference, m), ``dist`` (force offset, F), ``noise``
    (the unit-variance sensor noise), all (n,); ``modes`` (m, 3); ``p`` the parameter
    vector of :mod:`studies.proving.integrate`; ``info`` the truth's parameters."""
    u, y, x, info, w, extra = _simulate(case, seed)
    return {"u": u, "y": y, "x": x, "w": w, "info": info, **extra}


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
    u, y, x, info, w, _ = _simulate(case, seed, lim)
    if case.family == "out_of_scope":  # the position of an unrelated run
        other = "seeks" if case.excitation != "seeks" else "chirp"  # no frequency lines shared with the input
        if case.controller == "force":
            other = "steps" if case.excitation != "steps" else "chirp"
        _, y, x, *_ = _simulate(Case("null", 0.0, case.controller, other, case.rate_hz, case.samples, case.noise,
                                     case.motion_hz), seed + 7919)  # fmt: skip
    t = np.arange(case.samples) / case.rate_hz
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
        raise FloatingPointError(f"proving ground: {case} seed {seed} diverged")
    truth = {"family": case.family, "size": case.size, "expect": fam.expect, "verdicts": list(expected_verdicts(case.family)),
             "case": case.__dict__, "seed": seed, **info}  # fmt: skip
    if lim is not None:
        truth["u_max_late"] = lim
    ref = w.copy() if excitation and case.controller not in OPEN else None
    colour = "" if case.noise == "white" else f":{case.noise}"
    rec = Recording(t, u, y, None, source=f"proving:{case.family}:{case.size:g}:{case.controller}:{case.excitation}:"
                    f"{case.rate_hz:g}Hz{colour}:seed{seed}", meta={"truth": truth}, r=ref)  # fmt: skip
    return rec, truth


__all__ = ["ALL_EXCITATIONS", "CONTROLLERS", "Case", "EXCITATIONS", "FAMILIES", "FORCE_EXCITATIONS", "NOISES", "OPEN",
           "RATES", "SECOND", "accepted", "expected_verdicts", "recording", "sensor_noise", "trajectories"]

"""Stepped-sine measurement of the closed loop: L, S and T at the injection points.

One run per excitation level and compensator setting: the excitation current ``u_exc``
(A, added to the controller's output, :mod:`kernels.compose`) is a
sine held at each frequency in turn, ``level*sin(2*pi*f*(t - t_i))`` from the segment's
start ``t_i``: ``settle`` ticks (transients and the pivot's hysteresis loop become
periodic), then a window of exactly ``periods`` periods in whole samples (the
frequency is snapped to ``periods*fs/n``).  Over the window every logged signal ``s``
is correlated with the excitation's frequency (a single-bin DFT, no leakage)::

    S(f) = 2/n * sum_k s[k]*exp(-j*2*pi*f*(t_k - t_i))

computed as the least-squares fit of a sine together with an offset and a linear drift
(:func:`correlate`, the project's one demodulator :mod:`servo.frf.sine`), the same
number for a periodic signal and immune to a slow transient still decaying in the
window.

Signals (log columns): ``u`` the current command, ``u_n`` the controller's output with
the excitation (``u_n = u_pi + u_exc``), ``u_c`` the compensator's current, ``u_exc``,
``x``.  Two break points (docs/loop.md):

* at the controller's output (the compensated plant's input): ``S = U_n/U_exc``,
  ``L = -U_pi/U_n`` with ``U_pi = U_n - U_exc``, ``T = -U_pi/U_exc``; the plant the
  controller sees ``P = X/U_n`` and the controller ``C = -U_pi/X``.  This ``L`` is
  ``C*P``, the loop the design sets (:mod:`servo.loop.design`);
* at the current (the actuator's input): ``S_u = U/U_exc``, ``L_u = -U_fb/U`` with
  ``U_fb = U - U_exc`` (controller and compensator), ``T_u = -U_fb/U_exc``.

Without the compensator ``u_c = 0`` and the two coincide.  ``T = 1 - S`` holds per
definition (``U_n = U_pi + U_exc``) and is no check of anything.

The run is one session on any driver: the simulated drive (all-compiled fast path) or
a serial driver (tick by tick, ``make_driver``), so a board measures the same way.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from servo.config import Config
from servo.errors import ConfigError
from servo.frf.sine import demodulate
from servo.io.frequency_response import FrequencyResponse

#: The highest frequency a stepped sine measures, as a share of the Nyquist frequency
#: (a window of whole periods in whole samples; ``servo loop``'s default ``f_max``).
F_MAX_SHARE = 0.4

#: Log columns the estimator correlates.
SIGNALS = ("u", "u_n", "u_c", "u_exc", "x")


@dataclass(frozen=True)
class LoopSettings:
    """``f_min``/``f_max`` (Hz) and ``n_freq`` log-spaced frequencies; ``periods``
    measured per frequency; the settling before each window is the longer of
    ``settle_periods`` periods and ``settle_s`` seconds; ``levels``: excitation
    amplitudes (A); ``target_rel_err`` > 0: each frequency's amplitude is adapted to
    reach this relative random error of ``L`` (:func:`adapted_levels`), each level then
    the cap."""

    f_min: float = 20.0
    f_max: float = 2000.0
    n_freq: int = 25
    periods: int = 8
    settle_periods: int = 4
    settle_s: float = 0.02
    levels: tuple = (0.2e-3,)
    target_rel_err: float = 0.0

    def check(self, cfg: Config) -> "LoopSettings":
        """Refuse settings no measurement can honour (one :class:`ConfigError` line);
        ``f_max`` None becomes :data:`F_MAX_SHARE` of the Nyquist frequency."""
        nyq = 0.5 * cfg.run.sample_rate_hz
        if self.f_max is None:
            return dataclasses.replace(self, f_max=F_MAX_SHARE * nyq).check(cfg)
        if not (0.0 < self.f_min < self.f_max) or not math.isfinite(self.f_max):
            raise ConfigError(f"loop: need 0 < f_min < f_max (got {self.f_min:g}, {self.f_max:g} Hz)")
        if self.f_max > F_MAX_SHARE * nyq * (1 + 1e-12):
            raise ConfigError(f"loop: f_max {self.f_max:g} Hz must stay below 40 % of the Nyquist frequency "
                              f"({0.4 * nyq:g} Hz at {cfg.run.sample_rate_hz:g} Hz)")  # fmt: skip
        if self.n_freq < 4:
            raise ConfigError("loop: at least 4 frequencies (the margins interpolate between them)")
        if self.periods < 2 or self.settle_periods < 0 or not (0.0 <= self.settle_s <= 10.0):
            raise ConfigError("loop: periods >= 2, settle_periods >= 0 and 0 <= settle_s <= 10 s")
        if not self.levels or min(self.levels) <= 0.0 or not all(map(math.isfinite, self.levels)):
            raise ConfigError("loop: excitation levels must be positive")
        if not (0.0 <= self.target_rel_err < 1.0):
            raise ConfigError("loop: the target relative error must be in [0, 1)")
        if max(self.levels) >= cfg.controller.current_limit:
            raise ConfigError(f"loop: level {max(self.levels) * 1e3:g} mA reaches controller.current_limit "
                              f"({cfg.controller.current_limit * 1e3:g} mA)")  # fmt: skip
        return self


@dataclass
class Program:
    """The stepped-sine schedule: per segment i the frequency ``f[i]`` (Hz, snapped),
    its start tick ``start[i]`` (sine phase 0) and its measuring window
    ``[win[i, 0], win[i, 1])`` of ``periods`` whole periods; ``n_ticks`` in all."""

    f: np.ndarray
    start: np.ndarray
    win: np.ndarray
    periods: int
    dt: float

    @property
    def n_ticks(self) -> int:
        return int(self.win[-1, 1]) if len(self.win) else 0

    def excitation(self, level) -> np.ndarray:
        """``u_exc`` (A) per tick, shape ``(n_ticks,)``; ``level`` (A): one for every
        segment or one per segment."""
        u = np.zeros(self.n_ticks)
        levels = np.broadcast_to(np.asarray(level, dtype=float), self.f.shape)
        for f, lv, a, (_, b) in zip(self.f, levels, self.start, self.win):
            k = np.arange(b - a)
            u[a:b] = lv * np.sin(2.0 * np.pi * f * k * self.dt)
        return u


#: The largest head motion an adapted excitation may cause, as a share of ``drive.stroke``.
STROKE_SHARE = 0.01


def adapted_levels(cfg: Config, prog: Program, cap: float, target: float, compensation: bool) -> np.ndarray:
    """Excitation amplitudes (A, one per segment of ``prog``) for a relative random error
    ``target`` of the measured ``L``, from the design loop (drive model) and the sensor
    noise ``drive.position_noise`` (sigma_n, per tick).  The noise enters ``U_pi`` and
    ``U_n`` alike through ``C*S``; over a window of ``n`` ticks a single-bin estimate of it
    has amplitude ``sigma_n*sqrt(2/n)``, so ``L = -U_pi/U_n`` has the relative error
    ``sigma_n*sqrt(2/n)*|1 + L| / (|P|*A)``.  Hence

        A = sigma_n*sqrt(2/n)*|1 + L| / (|P|*target)

    bounded by :func:`_bounds`.  Other noise (a velocity sensor's, the pivot's) is not in
    the model: :func:`measure` runs a pilot at these amplitudes and scales each by its
    measured error over the target."""
    from servo.loop.design import loop_design

    d = loop_design(cfg, prog.f, "drive", compensated=compensation)
    n = (prog.win[:, 1] - prog.win[:, 0]).astype(float)
    need = cfg.drive.position_noise * np.sqrt(2.0 / n) * np.abs(1.0 + d.L) / (np.abs(d.P) * target)
    return np.minimum(need, _bounds(cfg, prog, cap, compensation))


def program(cfg: Config, s: LoopSettings, freqs=None) -> Program:
    """The schedule of ``s`` (or of the given frequencies, Hz) at ``cfg``'s sample rate.

    Each segment is a whole number of windows (``periods`` periods in whole samples),
    so its sine ends where it began, at phase 0: the excitation has no jump between
    frequencies.  The settling is the first whole windows, at least ``settle_periods``
    periods and ``settle_s`` seconds."""
    fs = cfg.run.sample_rate_hz
    fr = np.geomspace(s.f_min, s.f_max, s.n_freq) if freqs is None else np.asarray(freqs, dtype=float)
    f_act, start, win = [], [], []
    k = 0
    for f in fr:
        n = int(round(s.periods * fs / f))  # whole samples, exactly `periods` periods
        fa = s.periods * fs / n
        need = max(s.settle_periods / fa, s.settle_s) * fs
        settle = int(math.ceil(need / n - 1e-9)) * n
        f_act.append(fa)
        start.append(k)
        win.append((k + settle, k + settle + n))
        k += settle + n
    return Program(np.array(f_act), np.array(start, dtype=np.int64), np.array(win, dtype=np.int64).reshape(-1, 2),
                   s.periods, cfg.dt)  # fmt: skip


def correlate(log: dict[str, np.ndarray], prog: Program) -> tuple[dict, dict, dict]:
    """The complex amplitude at the frequency of each of :data:`SIGNALS` over each
    window, by the project's one stepped-sine demodulator
    (:func:`servo.frf.sine.demodulate`: a least-squares fit of a sine, an offset and a
    linear drift; over whole periods the sine's part equals the single-bin DFT, the
    drift term keeps a slow transient left in the window from leaking into it).
    Returns ``(whole, per_period, fraction)``: ``{signal: (n_f,) complex}``,
    ``{signal: (n_f, periods) complex}`` (one fit per period, for the spread) and
    ``{signal: (n_f,)}`` the fraction of the signal's variance about the offset and
    drift that the sine holds."""
    nf, p = len(prog.f), prog.periods
    whole = {s: np.zeros(nf, complex) for s in SIGNALS}
    per = {s: np.zeros((nf, p), complex) for s in SIGNALS}
    frac = {s: np.zeros(nf) for s in SIGNALS}
    for i, (f, a, (w0, w1)) in enumerate(zip(prog.f, prog.start, prog.win)):
        t = (np.arange(w0, w1) - a) * prog.dt
        fit = demodulate(np.column_stack([log[s][w0:w1] for s in SIGNALS]), f, t, p)
        for j, s in enumerate(SIGNALS):
            whole[s][i] = fit.amp[j]
            per[s][i] = fit.per_period[:, j]
            frac[s][i] = fit.fraction[j]
    return whole, per, frac


#: The responses a :class:`LoopMeasurement` gives: name -> (numerator, denominator, unit,
#: description).  Signals: U (u), Un (u_n), Uc (u_c), Ue (u_exc), X (x); Upi = Un - Ue,
#: Ufb = U - Ue; a leading "-" negates.
RESPONSES = {
    "L": ("-Upi", "Un", "-", "open loop at the controller output, -U_pi/U_n"),
    "S": ("Un", "Ue", "-", "sensitivity at the controller output, U_n/U_exc"),
    "T": ("-Upi", "Ue", "-", "complementary sensitivity, -U_pi/U_exc = 1 - S"),
    "P": ("X", "Un", "m/A", "plant the controller sees, X/U_n"),
    "C": ("-Upi", "X", "A/m", "controller, -U_pi/X"),
    "L_u": ("-Ufb", "U", "-", "open loop at the current, -U_fb/U"),
    "S_u": ("U", "Ue", "-", "input sensitivity at the current, U/U_exc"),
    "T_u": ("-Ufb", "Ue", "-", "complementary sensitivity at the current, -U_fb/U_exc = 1 - S_u"),
}


def _signal(d: dict, name: str):
    sign = -1.0 if name.startswith("-") else 1.0
    name = name.lstrip("-")
    base = {"U": "u", "Un": "u_n", "Uc": "u_c", "Ue": "u_exc", "X": "x"}
    if name == "Upi":
        return sign * (d["u_n"] - d["u_exc"])
    if name == "Ufb":
        return sign * (d["u"] - d["u_exc"])
    return sign * d[base[name]]


def _fraction_of(frac: dict, name: str) -> np.ndarray:
    name = name.lstrip("-")
    cols = {"U": ("u",), "Un": ("u_n",), "Uc": ("u_c",), "Ue": ("u_exc",), "X": ("x",),
            "Upi": ("u_n",), "Ufb": ("u",)}[name]  # fmt: skip
    return np.minimum.reduce([frac[c] for c in cols])


@dataclass
class LoopMeasurement:
    """One stepped-sine run at ``level`` (A), compensator on or off.  ``f`` (Hz, (n,));
    ``spectra``/``per_period``/``fraction`` as :func:`correlate` returns them;
    ``clipped``: ticks in the measuring windows where a current limit was reached;
    ``fast_ticks``: ticks in the windows where the compensator was in its FAST regime;
    ``link``: what a serial driver reported (None on the simulated drive)."""

    level: float
    compensation: bool
    f: np.ndarray
    spectra: dict
    per_period: dict
    fraction: dict
    clipped: int = 0
    fast_ticks: int = 0
    window_ticks: int = 0
    link: dict | None = None
    label: str = field(default="")
    levels_A: np.ndarray | None = None  # the amplitude at each frequency (A)

    def __post_init__(self):
        if not self.label:
            self.label = f"compensator {'on' if self.compensation else 'off'}, {self.level * 1e3:g} mA"

    def value(self, name: str) -> np.ndarray:
        """The response ``name`` of :data:`RESPONSES` at :attr:`f` (complex (n,))."""
        num, den, _, _ = RESPONSES[name]
        return _signal(self.spectra, num) / _signal(self.spectra, den)

    def response(self, name: str) -> FrequencyResponse:
        """``name`` as a :class:`~servo.io.frequency_response.FrequencyResponse`: ``rel_std``
        from the spread of the one-period estimates (``std/sqrt(periods)/|H|``),
        ``coherence`` the smaller fraction at the frequency of its two signals' variance."""
        num, den, unit, what = RESPONSES[name]
        H = self.value(name)
        Hi = _signal(self.per_period, num) / _signal(self.per_period, den)
        p = Hi.shape[1]
        rel = np.std(Hi, axis=1, ddof=1) / math.sqrt(p) / np.abs(H)
        coh = np.minimum(_fraction_of(self.fraction, num), _fraction_of(self.fraction, den))
        meta = {"method": "stepped sine, single-bin DFT", "what": what, "level_A": self.level,
                "compensation": self.compensation, "label": f"{name}, {self.label}"}  # fmt: skip
        return FrequencyResponse(self.f, H, coh, rel, unit, meta)


def run_config(cfg: Config, n_ticks: int) -> Config:
    """The config of one measuring run: ``n_ticks`` long, every tick logged, no scenario
    disturbance (a board applies its own config's; start ``servo emulate`` without one)."""
    return cfg.replace(run={"duration_s": n_ticks * cfg.dt, "log_every": 1}, scenario={"disturbance_amplitude": 0.0})


def run_log(cfg: Config, u_exc: np.ndarray, compensation: bool,
            make_driver: Callable | None = None) -> tuple[dict, dict | None]:  # fmt: skip
    """One closed-loop run with the excitation ``u_exc`` (A per tick): the log columns as
    arrays and what the driver reported about its link.  ``make_driver(cfg, inputs)``
    gives the driver (run tick by tick); None: the simulated drive, all compiled."""
    from servo.runtime.closedloop import MemoryLog, simulate
    from servo.runtime.controller import Controller
    from servo.runtime.loop import log_rows, run_closed_loop
    from servo.scenarios import ArrayInputs

    n = len(u_exc)
    rcfg = run_config(cfg, n)
    if rcfg.n_ticks != n:
        raise ValueError(f"tick count mismatch: {rcfg.n_ticks} != {n}")
    if make_driver is None:
        return simulate(rcfg, u_exc, compensation=compensation), None
    inputs = ArrayInputs(u_exc=u_exc)
    log = MemoryLog(log_rows(rcfg))
    driver = make_driver(rcfg, inputs)
    with driver:
        run_closed_loop(rcfg, driver, Controller(rcfg, compensation=compensation), inputs, log, fast=False, timing=False)
    return log.as_dict(), driver.report()


def measure(cfg: Config, s: LoopSettings, level: float, compensation: bool, make_driver: Callable | None = None,
            freqs=None) -> LoopMeasurement:  # fmt: skip
    """One stepped-sine run at ``level`` (A) on the simulated drive or ``make_driver``'s
    (see :func:`run_log`), at the frequencies of ``s`` (or ``freqs``, Hz)."""
    prog = program(cfg, s, freqs)
    amp = level
    if s.target_rel_err > 0:  # a pilot run at the model's amplitudes, then each scaled by its own error
        amp = adapted_levels(cfg, prog, level, s.target_rel_err, compensation)
        pilot = _measure(cfg, s, prog, amp, level, compensation, make_driver)
        rel = pilot.response("L").rel_std
        hi = _bounds(cfg, prog, level, compensation)
        amp = np.clip(np.where(np.isfinite(rel), amp * rel / s.target_rel_err, hi), 0.0, hi)
    return _measure(cfg, s, prog, amp, level, compensation, make_driver)


def _bounds(cfg: Config, prog: Program, cap: float, compensation: bool) -> np.ndarray:
    """The largest amplitude (A) at each segment: ``cap``, half the current limit, and a
    head motion of :data:`STROKE_SHARE` of the stroke on the design loop."""
    from servo.loop.design import loop_design

    d = loop_design(cfg, prog.f, "drive", compensated=compensation)
    stroke = STROKE_SHARE * cfg.drive.stroke / np.maximum(np.abs(d.P * d.S), 1e-300)
    return np.minimum(stroke, min(cap, 0.5 * cfg.controller.current_limit))


def _measure(cfg, s, prog, amp, level, compensation, make_driver) -> "LoopMeasurement":
    log, link = run_log(cfg, prog.excitation(amp), compensation, make_driver)
    whole, per, frac = correlate(log, prog)
    inside = np.zeros(prog.n_ticks, bool)
    for w0, w1 in prog.win:
        inside[w0:w1] = True
    c = cfg.controller
    own_limit = getattr(c.section, "holding_limit", getattr(c.section, "output_limit", np.inf))  # the kind's, if any
    clipped = int(np.count_nonzero(inside & ((np.abs(log["u"]) >= c.current_limit) | (np.abs(log["u_n"]) >= own_limit))))
    fast = int(np.count_nonzero(inside & (log["regime"] != 0.0))) if compensation else 0
    label = f"compensator {'on' if compensation else 'off'}, adapted to {100 * s.target_rel_err:g} % up to {level * 1e3:g} mA" \
        if s.target_rel_err > 0 else ""
    return LoopMeasurement(level, compensation, prog.f, whole, per, frac, clipped, fast, int(inside.sum()), link, label,
                           np.broadcast_to(np.asarray(amp, float), prog.f.shape).copy())


__all__ = ["RESPONSES", "SIGNALS", "LoopMeasurement", "LoopSettings", "Program", "adapted_levels", "correlate", "measure", "program",
           "run_config", "run_log"]

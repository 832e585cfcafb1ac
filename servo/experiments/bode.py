"""Swept-sine frequency response from VCM current to position (paper Fig. 7-10).

Stepped sine: at each frequency the excitation ``A*sin(2*pi*f*t)`` is added to the PI
holding loop's output for ``settle`` (transients and the pivot's hysteresis state die
out) and then ``periods`` whole periods (the frequency is snapped so that the measuring
window holds exactly that many periods in whole samples).  The input is the nominal
input ``u_n`` (= the VCM current ``u`` without compensation; ``u - u_c`` with it, the
input of the compensated plant of eq. 10), the output the measured position.  Both are
demodulated over the window by the project's one stepped-sine demodulator
(:func:`servo.frf.sine.demodulate`: the least-squares fit of a sine with an offset and a
linear drift, over whole periods the single-bin DFT plus a trend, no leakage)::

    H(jw) = X(w) / U(w)

This is the loop-independent plant estimate: the excitation enters outside the plant, so
the holding loop cancels out of the ratio.  Per point, besides ``H``:

* ``std``: the standard deviation of ``H`` from the spread of the one-period estimates
  (``std(H_i)/sqrt(n_periods)``, :meth:`servo.frf.sine.SineFit.ratio`), a
  noise/nonstationarity estimate;
* ``coherence``: the fraction of the output's variance about its offset and drift at
  the excitation frequency, ``|X|^2/2 / var(x - c0 - c1*t)``; 1 for a linear noise-free
  plant, lower with noise or harmonics (the pivot's nonlinearity).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from servo.config import Config
from servo.errors import ConfigError, UnstableLoop
from servo.frf.estimate import WelchSettings, spectra
from servo.frf.sine import demodulate
from servo.runtime.closedloop import simulate
from servo.io.frequency_response import FrequencyResponse


@dataclass(frozen=True)
class SweepSettings:
    """``levels``: excitation amplitudes (A); ``f_min``/``f_max`` (Hz) and ``n_freq``
    log-spaced points; ``periods`` measured per point; ``settle_periods`` and
    ``settle_s``: the settling time is the longer of the two."""

    levels: tuple = (0.2e-3, 1e-3, 4e-3, 16e-3)
    f_min: float = 10.0
    f_max: float = 1000.0
    n_freq: int = 30
    periods: int = 8
    settle_periods: int = 4
    settle_s: float = 0.03


@dataclass
class Sweep:
    """One Bode sweep at one ``level`` (A), compensator on or off.  Arrays (n_freq,):
    ``f`` (Hz), ``H`` (complex, m/A), ``std`` (m/A), ``coherence`` (-), ``x_amp`` (m,
    position amplitude at f)."""

    level: float
    compensation: bool
    f: np.ndarray
    H: np.ndarray
    std: np.ndarray
    coherence: np.ndarray
    x_amp: np.ndarray
    label: str = field(default="")

    @property
    def mag_db(self) -> np.ndarray:
        return 20 * np.log10(np.abs(self.H))

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase (deg), unwrapped and shifted so the first point lies in (-360, 0]."""
        ph = np.unwrap(np.angle(self.H))
        ph -= 2 * np.pi * math.ceil(ph[0] / (2 * np.pi))
        return np.degrees(ph)

    def response(self) -> FrequencyResponse:
        """The sweep as a :class:`~servo.io.frequency_response.FrequencyResponse` (m/A;
        ``rel_std`` = ``std/|H|``), the form ``servo bode`` writes to ``frd.npz``."""
        meta = {"method": "stepped sine", "level_A": self.level, "compensation": self.compensation,
                "x_amp_m": self.x_amp.tolist()}  # fmt: skip
        return FrequencyResponse(self.f, self.H, self.coherence, self.std / np.abs(self.H), "m/A", meta)

    def frd(self):
        """The sweep as :class:`control.FrequencyResponseData` (omega in rad/s)."""
        return self.response().to_control()


def check_holding_loop(cfg: Config, seconds: float = 2.0, name: str = "the drive") -> None:
    """Refuse a drive on which the PI holding loop is unstable (a flexible mode, too much
    gain): run ``seconds`` unexcited, with and without compensation, and raise a one-line
    :class:`~servo.errors.ConfigError` if the position's RMS in the last tenth exceeds 10x
    that of the first tenth and 10 nm.  A sweep on such a drive would measure the
    oscillation, not the plant.  The run's watchdog is told to let a command sit at its
    limit (``run.fault_limit_share = 1``), so that the check sees the oscillation and
    names its frequency; a position that leaves the stroke is still refused."""
    n = int(round(seconds / cfg.dt))
    watched = cfg.replace(run={"fault_limit_share": 1.0})
    for comp in (False, True):
        try:
            x = simulate(watched, np.zeros(n), compensation=comp)["x"]
        except UnstableLoop as exc:
            raise ConfigError(f"the PI holding loop is unstable on {name} (compensation {'on' if comp else 'off'}): "
                              f"{exc}") from None  # fmt: skip
        k = n // 10
        first, last = np.std(x[:k]), np.std(x[-k:])
        if last > 10 * first and last > 1e-8:
            sp = spectra({"x": x[-k:]}, cfg.dt, WelchSettings(nperseg=k, overlap=0.0, window="boxcar").check(k), [])
            f = sp.f[1:][np.argmax(sp.P[("x", "x")][1:])]  # the periodogram's peak
            raise ConfigError(
                f"the PI holding loop is unstable on {name} (compensation {'on' if comp else 'off'}): the position RMS "
                f"grows from {first * 1e9:.3g} nm to {last * 1e9:.3g} nm in {seconds:g} s, oscillating at {f:.0f} Hz; "
                "lower controller.pi.kp/ki/kd or change the drive's modes"
            )


#: Most frequencies a sweep may hold, and most samples one point may simulate (its
#: settling and measuring window; several float64 arrays of it are held at once).
MAX_FREQUENCIES = 1000
MAX_POINT_SAMPLES = 1 << 24


def check_settings(s: SweepSettings, fs: float) -> None:
    """Refuse (ValueError, one line) a sweep beyond the budgets above at sample rate
    ``fs`` (Hz): the point at ``f_min`` is the longest."""
    if s.n_freq > MAX_FREQUENCIES:
        raise ValueError(f"{s.n_freq} frequencies, more than the {MAX_FREQUENCIES} a sweep may hold")
    n = max(s.settle_periods / s.f_min, s.settle_s) * fs + s.periods * fs / s.f_min
    if n > MAX_POINT_SAMPLES:
        raise ValueError(f"the point at {s.f_min:g} Hz simulates {n:.3g} samples ({s.periods} periods at {fs:g} Hz), "
                         f"more than the {MAX_POINT_SAMPLES} a point may; fewer --periods or a higher --f-min")  # fmt: skip


def frequencies(s: SweepSettings) -> np.ndarray:
    return np.geomspace(s.f_min, s.f_max, s.n_freq)


def sine_point(cfg: Config, f: float, level: float, s: SweepSettings, compensation: bool) -> tuple:
    """Measure one point.  Returns ``(f_actual, H, std, coherence, x_amp)``."""
    fs = 1.0 / cfg.dt
    L = int(round(s.periods * fs / f))  # measuring window, whole samples
    f_act = s.periods * fs / L  # exactly `periods` periods in L samples
    settle = int(math.ceil(max(s.settle_periods / f_act, s.settle_s) * fs))
    n = settle + L
    t = np.arange(n) * cfg.dt
    log = simulate(cfg, level * np.sin(2 * np.pi * f_act * t), compensation=compensation)
    fit = demodulate(np.column_stack([log["x"][settle:], log["u_n"][settle:]]), f_act, t[settle:], s.periods)
    H, std = fit.ratio(0, 1)
    X = fit.amp[0]
    return f_act, H, std, float(fit.fraction[0]), float(abs(X))


def sweep(cfg: Config, level: float, s: SweepSettings, compensation: bool, progress=None) -> Sweep:
    """A whole sweep at ``level`` (A).  ``progress(i, n)`` is called after each point."""
    fr = frequencies(s)
    out = np.zeros((len(fr), 5), dtype=complex)
    for i, f in enumerate(fr):
        out[i] = sine_point(cfg, f, level, s, compensation)
        if progress:
            progress(i + 1, len(fr))
    return Sweep(level, compensation, out[:, 0].real, out[:, 1], out[:, 2].real, out[:, 3].real, out[:, 4].real,
                 label=f"{level * 1e3:g} mA, compensation {'on' if compensation else 'off'}")  # fmt: skip


__all__ = ["Sweep", "SweepSettings", "check_holding_loop", "frequencies", "sine_point", "sweep"]

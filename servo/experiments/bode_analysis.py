"""Numbers read off the Bode sweeps: the resonance per level (Fig. 7), the double-integrator
claims with compensation (Fig. 8), and the second drive of Fig. 9-10.

* :func:`resonance`: the equivalent linear plant ``1/H = k - J*w^2 + j*c*w`` fitted by
  least squares to the points below ``f_max`` gives ``f_n = sqrt(k/J)/(2*pi)`` and the
  damping ratio ``zeta = c/(2*sqrt(k*J))`` -- the pivot's describing function at that
  level.  The frequency of the measured magnitude peak is reported too.
* :func:`linearity`: over the band below ``band_max`` (Hz): the spread of the magnitude
  across levels (max - min, dB: worst, RMS over the band, and the frequency above which
  it stays within 1 dB), the slope of each level's magnitude (dB/decade, least squares on
  log10 f) and the phase range.
"""
from __future__ import annotations

import numpy as np

from servo.config import Config
from servo.experiments.bode import Sweep


def resonance(sw: Sweep, f_max: float = 300.0, delay_s: float = 0.0) -> dict:
    """Equivalent second-order fit of the points below ``f_max`` (Hz), after removing a
    known pure delay ``delay_s`` (s; on the simulated drive its input delay plus half a
    sample of zero-order hold), whose phase lag would otherwise read as negative damping."""
    m = sw.f <= f_max
    w = 2 * np.pi * sw.f[m]
    G = np.exp(-1j * w * delay_s) / sw.H[m]  # k - J w^2 + j c w
    A = np.zeros((2 * m.sum(), 3))
    A[: m.sum(), 0] = 1.0
    A[: m.sum(), 1] = -(w**2)
    A[m.sum():, 2] = w
    b = np.concatenate([G.real, G.imag])
    k, J, c = np.linalg.lstsq(A, b, rcond=None)[0]
    f_n = float(np.sqrt(k / J) / (2 * np.pi)) if k > 0 and J > 0 else float("nan")
    zeta = float(c / (2 * np.sqrt(k * J))) if k > 0 and J > 0 else float("nan")
    peak = int(np.argmax(sw.mag_db[m]))
    return {"level_A": sw.level, "f_n_hz": f_n, "zeta": zeta, "k_A_per_m": float(k), "J": float(J), "c": float(c),
            "peak_hz": float(sw.f[m][peak]), "peak_db": float(sw.mag_db[m][peak])}  # fmt: skip


def linearity(sweeps: list[Sweep], band_max: float) -> dict:
    """Spread across levels, slope per level and phase range below ``band_max`` (Hz)."""
    f = sweeps[0].f
    m = f <= band_max
    mags = np.array([s.mag_db[m] for s in sweeps])
    phases = np.array([s.phase_deg[m] for s in sweeps])
    spread = mags.max(axis=0) - mags.min(axis=0)
    slopes = [float(np.polyfit(np.log10(f[m]), mg, 1)[0]) for mg in mags]
    wide = np.flatnonzero(spread > 1.0)
    above = float(f[m][wide[-1] + 1]) if wide.size and wide[-1] + 1 < spread.size else (
        float(f[m][0]) if not wide.size else float("nan"))  # fmt: skip
    return {
        "band_hz": [float(f[m][0]), float(f[m][-1])],
        "spread_db_max": float(spread.max()),
        "spread_db_rms": float(np.sqrt(np.mean(spread**2))),
        "spread_below_1db_above_hz": above,
        "spread_worst_hz": float(f[m][int(np.argmax(spread))]),
        "slope_db_per_decade": {f"{s.level * 1e3:g} mA": sl for s, sl in zip(sweeps, slopes)},
        "phase_deg_min": float(phases.min()),
        "phase_deg_max": float(phases.max()),
    }


def loop_delay(cfg: Config) -> float:
    """Pure delay (s) between command and response on the simulated drive: the input
    delay, the link latency and half a sample of zero-order hold."""
    return cfg.drive.input_delay_s + cfg.link.loop_latency_ticks * cfg.dt + 0.5 * cfg.dt


def band_max(cfg: Config) -> float:
    """Top of "the band below the first flexible mode": a third of the lowest mode
    frequency (1 kHz on the default drive), where the modes move the magnitude by less
    than ~0.6 dB and the delays (10 us input + half a sample of hold) cost < 8 degrees."""
    modes = cfg.drive.mode_hz
    return (min(modes) / 3.0) if modes else cfg.run.sample_rate_hz / 20


def second_drive(cfg: Config) -> Config:
    """The "other HDD" of Fig. 9-10: the benchmark's perturbations of docs/model.md section 5
    (mode frequencies -5..+2.5 %, damping -50..+100 %, modal gains +-20 %) and the pivot
    and bias changed by tens of percent (sigma +30 %, Ha -25 %, B +40 %, K -30 %, h0 +25 %).
    The compensator keeps the nominal drive's values (no retuning).  The 7 kHz mode's
    damping is doubled, not halved: halved, it destabilises the default holding loop
    (which has no notch filter) within a second, with or without compensation."""
    d = cfg.drive
    fmul = [0.95, 1.025, 0.97, 1.01, 0.98, 1.025]
    zmul = [0.5, 2.0, 1.5, 2.0, 0.5, 1.0]
    gmul = [1.2, 0.8, 1.2, 0.9, 1.1, 0.8]
    n = len(d.mode_hz)
    pick = lambda mul, i: mul[i % len(mul)]  # noqa: E731
    return cfg.replace(drive={
        "sigma": d.sigma * 1.3, "Ha": d.Ha * 0.75, "B": d.B * 1.4, "K": d.K * 0.7, "h0": d.h0 * 1.25,
        "mode_hz": [d.mode_hz[i] * pick(fmul, i) for i in range(n)],
        "mode_zeta": [d.mode_zeta[i] * pick(zmul, i) for i in range(n)],
        "mode_gain": [d.mode_gain[i] * pick(gmul, i) for i in range(n)],
    })  # fmt: skip


__all__ = ["band_max", "linearity", "loop_delay", "resonance", "second_drive"]

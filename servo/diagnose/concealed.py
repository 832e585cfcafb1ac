"""Recordings with a concealed effect, made on the simulated drive, to test a diagnosis
blind: the test knows what was put in, the command does not.

A *null* drive has exactly the physics the paper's baseline ``[J, B, Fc, K, h0]`` can
represent: a rigid body, viscous friction, a Coulomb friction with exact sticking
(``Fc = Fs``), the bias ``K*x + h0``; the pivot's Dahl element is switched off (a Dahl
level of 1e-12 A with a Dahl length of 1 m: a negligible spring that never saturates), there are no flexible modes, no input delay, no quantisation, and the
sensor has its 1 nm noise.  Each effect adds one piece of physics to it at a given size.

The scenario makes the effects hard to see: the PI holding loop (100 Hz) tracks a
long-stroke reference (three sines, +-1.3 mm, 3-37 Hz, random phases) and a band-limited
random current (20-1000 Hz, 2 mA RMS) is added to its output, for 1 s at 50 kHz.  The
strokes are a thousand times the Dahl length, so a hysteresis shows only in the few
milliseconds after each reversal; a mode sits in a band where the input has little
power; a saturation clips a fraction of a percent of the samples.  For the terms of the baseline itself
(Coulomb, viscous, stiffness, offset) the diagnosis runs with a baseline that lacks the
term, and the others (in particular the offset and the stiffness, which share a column
with much of it) absorb what they can.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from servo import physics
from servo.config import Config
from servo.diagnose.terms import VOCABULARY, Effect
from servo.runtime.closedloop import simulate
from servo.io.recording import Recording

RATE_HZ = 50_000.0
NULL_DRIVE = dict(
    J=1.0e-3, B=2.0e-3, Fc=1.0e-3, Fs=1.0e-3, K=0.1, h0=2.0e-3, Ha=1e-12, sigma=1e-12,
    mode_hz=[], mode_zeta=[], mode_gain=[], input_delay_s=0.0, position_quantum=0.0, sensor_cutoff_hz=0.0,
    position_noise=1e-9, velocity_noise=1e-6, current_limit=1.0,
)  # fmt: skip
DEFAULT_BASELINE = "J,B,Fc,K,h0"


#: the effects of the study, in the vocabulary's order: each effect module's
#: :attr:`~servo.physics.base.Effect.study` (its sizes, its baseline, its drive fields)
EFFECTS = {name: physics.EFFECTS[name].study for name in VOCABULARY if physics.EFFECTS[name].study is not None}


@dataclass(frozen=True)
class Scenario:
    """The excitation: reference sines (amplitudes m, frequencies Hz), the random
    current's RMS (A) and band (Hz), duration (s), fade-in (s)."""

    ref_amp: tuple = (1.0e-3, 0.3e-3, 0.1e-3)
    ref_hz: tuple = (3.0, 11.0, 37.0)
    exc_rms: float = 2e-3
    exc_band: tuple = (20.0, 1000.0)
    duration_s: float = 1.0
    fade_s: float = 0.02


def scenario_inputs(sc: Scenario, seed: int, dt: float = 1 / RATE_HZ) -> tuple[np.ndarray, np.ndarray]:
    """Reference (m) and excitation current (A), one per tick, from ``seed``."""
    rng = np.random.default_rng(seed)
    n = int(round(sc.duration_s / dt))
    t = np.arange(n) * dt
    fade = np.clip(t / sc.fade_s, 0, 1)
    fade = 0.5 - 0.5 * np.cos(np.pi * fade)
    ph = rng.uniform(0, 2 * np.pi, len(sc.ref_hz))
    r = sum(a * (np.sin(2 * np.pi * f * t + p) - np.sin(p)) for a, f, p in zip(sc.ref_amp, sc.ref_hz, ph))
    b, a = signal.butter(2, [sc.exc_band[0] * 2 * dt, sc.exc_band[1] * 2 * dt], btype="band")
    e = signal.lfilter(b, a, rng.standard_normal(n))
    e *= sc.exc_rms / e.std()
    return fade * r, fade * e


def drive_config(effect: str | None, size: float, seed: int) -> Config:
    """The simulated drive of a concealed recording (noise seeded by ``seed``)."""
    drive = dict(NULL_DRIVE)
    if effect is not None:
        drive.update(EFFECTS[effect].drive(size))
    return Config().replace(drive=drive, run={"seed": int(seed), "sample_rate_hz": RATE_HZ})


def concealed_recording(effect: str | None, size: float = 0.0, seed: int = 0, scenario: Scenario = Scenario()
                        ) -> tuple[Recording, dict]:  # fmt: skip
    """A recording of the null drive (``effect`` None) or of the null drive plus one
    effect of ``size``.  Returns the recording (t, u the command, x the measured
    position) and the truth (what a diagnosis should find, with the drive's fields)."""
    cfg = drive_config(effect, size, seed)
    r, e = scenario_inputs(scenario, seed, cfg.dt)
    calibrate = EFFECTS[effect].calibrate if effect else None
    if calibrate is not None:  # a size measured on the run itself (a saturation's clipped share)
        cfg = cfg.replace(drive=calibrate(simulate(cfg, e, r=r), size))
    log = simulate(cfg, e, r=r)
    truth = {"physics": effect, "size": size, "seed": seed,
             "drive": {k: getattr(cfg.drive, k) for k in sorted(NULL_DRIVE) + ["stroke"]
                       + sorted(EFFECTS[effect].drive(size) if effect else [])},
             "baseline": EFFECTS[effect].baseline if effect else DEFAULT_BASELINE}  # fmt: skip
    rec = Recording(log["t"], log["u"], log["x"], None, source=f"concealed:{effect or 'null'}:{size:g}:seed{seed}",
                    meta={"truth": truth})  # fmt: skip
    return rec, truth


__all__ = ["DEFAULT_BASELINE", "EFFECTS", "Effect", "NULL_DRIVE", "Scenario", "concealed_recording", "drive_config",
           "scenario_inputs"]  # fmt: skip

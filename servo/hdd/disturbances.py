"""The benchmark's disturbances as arrays for a run of ``n`` ticks (as a run's inputs:
:mod:`servo.scenarios.hdd_benchmark`).

How the benchmark scales its noise (``scl = sqrt(2*Ts)``), as implemented here:

The benchmark generates each random signal as ``whitenoise(N, T) * Amp`` where
``whitenoise`` makes a white sequence of *unit one-sided power spectral density* at
sample period ``T`` (standard deviation ``1/sqrt(2*T)``: variance = PSD * bandwidth
``1/(2T)``) and ``Amp = value * scl``, ``scl = sqrt(2*Ts)``.  So every ``Amp`` is an
amplitude spectral density (unit/sqrt(Hz), one-sided), independent of the rate the signal
is generated at, and the "1 sigma" values of the parameter files are the standard
deviations *when sampled at the PES period Ts* (the force disturbance's comment says so:
"1 sigma ... with sampling Ts").  Then:

* sensor noise, generated at ``Ts``: 1 sigma = 1.5e-2 track = 3.81 nm per PES sample;
* force disturbance, generated at the input period ``Tu = Ts/2``: ASD ``1e-4*scl``
  A/sqrt(Hz), 1 sigma = ``1e-4*sqrt(Ts/Tu)`` = 1.41e-4 A per tick (1e-4 A at ``Ts``);
* flutter: nine resonances ``Amp_i*2*zeta_i*w_i^2 / (s^2 + 2*zeta_i*w_i*s + w_i^2)``
  driven by unit-PSD white noise at ``Ty = Ts`` (zero-order hold, exact discretisation,
  from rest as the benchmark's ``lsim``): ``Amp_i`` (tracks * scl) is the peak of each
  resonance's ASD;
* RRO: harmonics 1, 2, 3 of the spindle (120, 240, 360 Hz) of 0.15, 0.03, 0.006 track
  with uniformly random phases, plus the benchmark's written-in runout (the package's
  ``RROSequence.mat``: 220 samples, 9.2 % of a track peak to peak; ``SetRRO.m`` adds it)
  when the caller points ``package`` at a copy of the benchmark package
  (:func:`written_in_rro`), repeated exactly every revolution (220 PES samples).  Without
  the package the RRO is the three harmonics alone, as the parameter files state them
  (the package's own ``SetDistParam.m`` falls back the same way when the file is absent).

(The alternative reading, unit *two-sided* PSD, would make every random level sqrt(2)
larger; the benchmark's own numbers for its reference design, NRPE 3 sigma 7-10 % of a
track on version 1, agree with this one: :mod:`studies.hdd.evaluate` reproduces them.)

Signs: the benchmark's PES is ``y + flutter + RRO + noise`` and its controller acts on
``-PES``.  Here the runout ``flutter + RRO`` is the track's motion seen by the head; a run
gets it as the reference ``r = -(flutter + RRO)``, so ``e = r - y_meas = -PES``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import io, signal

from servo.hdd.benchmark import Benchmark, benchmark


@dataclass(frozen=True)
class Disturbances:
    """One realisation.  PES-rate arrays ``(n_pes,)`` in m: ``rro``, ``flutter``, ``noise``
    (the sensor noise, for a linear simulation; a run draws its own from
    ``drive.position_noise = noise_std``); tick-rate ``force`` ``(n_ticks,)`` in A;
    ``fs`` tick rate (Hz), ``pes_every`` ticks per PES sample; ``rro_phases`` (rad)."""

    fs: float
    pes_every: int
    rro: np.ndarray
    flutter: np.ndarray
    noise: np.ndarray
    force: np.ndarray
    noise_std: float
    force_std: float
    rro_phases: np.ndarray
    rro_revolution: np.ndarray  # one revolution of the RRO (m), (sectors,): rro repeats it
    written_in: bool = False  # the package's written-in RRO is part of rro

    @property
    def runout(self) -> np.ndarray:
        """Track runout seen by the head at the PES rate (m): RRO + flutter."""
        return self.rro + self.flutter

    def held(self, x: np.ndarray) -> np.ndarray:
        """A PES-rate array at the tick rate (each value held ``pes_every`` ticks), ``(n_ticks,)``."""
        return np.repeat(x, self.pes_every)[: self.force.shape[0]]

    def reference(self) -> np.ndarray:
        """The run's reference (m) at the tick rate: ``-(RRO + flutter)``, held between PES samples."""
        return -self.held(self.runout)


def flutter_filters(bench: Benchmark):
    """``(b, a)`` of each flutter resonance discretised with a zero-order hold at ``Ts``,
    input: unit-PSD white noise (its samples of std ``1/sqrt(2*Ts)``), output in tracks."""
    out = []
    for f, z, a in zip(bench.flutter_hz, bench.flutter_zeta, bench.flutter_amp):
        w = 2 * np.pi * f
        pk = a * bench.scl
        b, den, _ = signal.cont2discrete(([pk * 2 * z * w * w], [1.0, 2 * z * w, w * w]), bench.Ts, method="zoh")
        out.append((np.ravel(b), np.ravel(den)))
    return out


#: The written-in runout's file in the benchmark package (``hdd_distparam_v2.m`` loads it).
RRO_FILE = "RROSequence.mat"


def written_in_rro(package, sectors: int = 220) -> np.ndarray:
    """The benchmark's written-in runout, one revolution (tracks, ``(sectors,)``), read
    from ``RROSequence.mat`` in ``package`` (a folder: the user's copy of the benchmark
    package).  Raises ValueError (one line) when the file is missing or not the
    benchmark's (variable ``RROSequence``, ``sectors`` finite samples)."""
    path = Path(package) / RRO_FILE
    if not path.is_file():
        raise ValueError(f"{path}: not found (point it at a copy of the NSS HDD benchmark package)")
    try:
        seq = io.loadmat(str(path)).get("RROSequence")
    except (ValueError, TypeError, OSError, io.matlab.MatReadError) as exc:
        raise ValueError(f"{path}: not a MATLAB file ({exc})") from None
    seq = None if seq is None else np.ravel(np.asarray(seq, dtype=float))
    if seq is None or seq.shape != (sectors,) or not np.all(np.isfinite(seq)):
        raise ValueError(f"{path}: no RROSequence of {sectors} finite samples")
    return seq


def generate(n_ticks: int, version: int = 2, seed: int = 0, fs: float | None = None, package=None) -> Disturbances:
    """The benchmark's disturbances for ``n_ticks`` ticks at ``fs`` (Hz, default ``2/Ts``;
    ``fs*Ts`` must be a whole number of ticks per PES sample).  Deterministic in ``seed``:
    each source draws from its own stream of ``numpy.random.SeedSequence(seed)``.
    ``package``: folder of a copy of the benchmark package whose written-in runout
    (:func:`written_in_rro`) is added to the RRO; None: the three harmonics alone."""
    b = benchmark(version)
    written = None if package is None or str(package) == "" else written_in_rro(package, b.sectors)
    fs = 2.0 / b.Ts if fs is None else float(fs)
    pes_every = int(round(fs * b.Ts))
    if pes_every < 1 or abs(fs * b.Ts - pes_every) > 1e-9:
        raise ValueError(f"fs = {fs:g} Hz: need a whole number of ticks per PES period Ts = {b.Ts:.6g} s")
    if n_ticks < 1:
        raise ValueError("n_ticks must be >= 1")
    n_pes = -(-n_ticks // pes_every)
    g_force, g_noise, g_flutter, g_rro = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4))
    Tp, Ts = b.Tp, b.Ts
    noise_std = b.sensor_noise * b.scl / np.sqrt(2 * Ts) * Tp
    force_std = b.force_noise * b.scl / np.sqrt(2 / fs)
    force = g_force.standard_normal(n_ticks) * force_std
    noise = g_noise.standard_normal(n_pes) * noise_std
    flutter = np.zeros(n_pes)
    for num, den in flutter_filters(b):
        flutter += signal.lfilter(num, den, g_flutter.standard_normal(n_pes) / np.sqrt(2 * Ts))
    flutter *= Tp
    phases = g_rro.uniform(0.0, 2 * np.pi, len(b.rro_harmonics))
    t = np.arange(b.sectors) * Ts
    rev = sum(a * np.sin(2 * np.pi * h * b.spindle_hz * t + ph) for h, a, ph in zip(b.rro_harmonics, b.rro_amp, phases))
    if written is not None:
        rev = rev + written
    rev = np.asarray(rev * Tp, float)
    rro = rev[np.arange(n_pes) % b.sectors]  # exactly periodic per revolution
    return Disturbances(fs, pes_every, rro, flutter, noise, force, float(noise_std), float(force_std), phases, rev,
                        written is not None)  # fmt: skip

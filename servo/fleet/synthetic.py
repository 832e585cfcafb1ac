"""A synthetic fleet for tests and demos: drives with spreads, a known few with a concealed defect.

Every drive is the *null* drive of :mod:`servo.diagnose.concealed` (exactly the physics
of the baseline ``[J, B, Fc, K, h0]``) with its baseline parameters spread
(:data:`SPREAD`: a normal with a relative standard deviation per field, ``Fs = Fc``
kept), recorded under the concealed-effect scenario (the PI holding loop tracking
three sines plus a band-limited random current) with a sensor-noise seed of its own.
A known set of drives (``defects`` of them, chosen at random) also carries one defect
of :data:`DEFECTS` (taken in turn) at the size :mod:`servo.diagnose.concealed` calls
clearly detectable (``Effect.clear``): extra hysteresis, a resonance, a saturation of
the input, an asymmetric friction.  ``servo fleet diagnose`` on the fleet should name
exactly those drives, each with its defect.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servo.config import Config
from servo.diagnose.concealed import EFFECTS, NULL_DRIVE, RATE_HZ, Scenario, scenario_inputs
from servo.errors import ConfigError
from servo.runtime.closedloop import simulate
from servo.io import progress
from servo.io.atomic import atomic_write, write_json
from servo.io.outdir import staged
from servo.fleet.spec import check_seed
from servo.io.recording import MIN_SAMPLES, Recording

#: relative standard deviation of each baseline field across the fleet
SPREAD = {"J": 0.03, "B": 0.10, "Fc": 0.10, "K": 0.20, "h0": 0.20}
DEFECTS = ("hysteresis", "resonance", "input_saturation", "asymmetric_friction")


@dataclass(frozen=True)
class SyntheticDrive:
    """One drive: ``name``, its ``drive`` fields (beyond the null drive's), the
    ``defect`` it carries (None) and its ``size``, the noise and excitation ``seed``."""

    name: str
    drive: dict
    defect: str | None
    size: float
    seed: int


def check_duration(duration_s: float) -> None:
    """Refuse (one :class:`~servo.errors.ConfigError` line) a recording length the
    recording readers would refuse to read back (:data:`servo.io.tables.MAX_SAMPLES` at
    :data:`RATE_HZ`), before anything is simulated or written."""
    from servo.io.tables import MAX_SAMPLES

    if not MIN_SAMPLES / RATE_HZ <= duration_s <= MAX_SAMPLES / RATE_HZ:  # (1e-6 s was 0 samples, then 7 lines)
        raise ConfigError(f"--duration {duration_s!r}: expected {MIN_SAMPLES / RATE_HZ:g} to {MAX_SAMPLES / RATE_HZ:g} s "
                          f"per recording ({MIN_SAMPLES} to {MAX_SAMPLES} samples at {RATE_HZ:g} Hz, what a recording "
                          "needs and may hold)")  # fmt: skip


def synthetic_drives(n: int, defects: int, seed: int = 0) -> list[SyntheticDrive]:
    """``n`` drives of which ``defects`` carry a defect (see module doc); reproducible
    from ``seed``."""
    if n < 1:
        raise ConfigError(f"fleet: a synthetic fleet needs at least one drive, got {n}")
    if not 0 <= defects <= n:
        raise ConfigError(f"fleet: {defects} defective drives in a fleet of {n}")
    check_seed(seed)
    rng = np.random.default_rng(seed)
    bad = {int(i): DEFECTS[k % len(DEFECTS)] for k, i in enumerate(sorted(rng.choice(n, defects, replace=False)))}
    width = max(4, len(str(n - 1)))
    out = []
    for i in range(n):
        d = {k: NULL_DRIVE[k] * (1.0 + s * rng.standard_normal()) for k, s in SPREAD.items()}
        d["Fs"] = d["Fc"]
        eff = bad.get(i)
        out.append(SyntheticDrive(f"drive{i:0{width}d}", d, eff, EFFECTS[eff].clear if eff else 0.0, seed * 100_003 + i))
    return out


def record(sd: SyntheticDrive, duration_s: float = 0.5) -> Recording:
    """The recording of one synthetic drive (t, u the command, x the measured position)."""
    drive = {**NULL_DRIVE, **sd.drive}
    if sd.defect is not None:
        drive.update(EFFECTS[sd.defect].drive(sd.size))
    cfg = Config().replace(drive=drive, run={"seed": int(sd.seed), "sample_rate_hz": RATE_HZ})
    r, e = scenario_inputs(Scenario(duration_s=duration_s), sd.seed, cfg.dt)
    calibrate = EFFECTS[sd.defect].calibrate if sd.defect is not None else None
    if calibrate is not None:  # a size measured on the run itself (a saturation's clipped share)
        cfg = cfg.replace(drive=calibrate(simulate(cfg, e, r=r), sd.size))
    log = simulate(cfg, e, r=r)
    return Recording(log["t"], log["u"], log["x"], None, source=f"synthetic:{sd.name}")


def _write_npz(path: Path, rec: Recording) -> None:
    def w(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, t=rec.t, u=rec.u, x=rec.x)

    atomic_write(path, w)


def write_fleet(out: str | Path, drives: list[SyntheticDrive], duration_s: float = 0.5) -> Path:
    """Write each drive's recording (``<name>.npz``, columns t, u, x), ``manifest.csv``
    (drive, path) and ``truth.json`` (each drive's fields and defect) into the new (or
    empty) folder ``out``, staged (:func:`servo.io.outdir.staged`: complete or absent);
    returns the manifest's path."""
    with staged(out) as tmp:
        _write_fleet(tmp, drives, duration_s)
    return Path(out) / "manifest.csv"


def _write_fleet(out: Path, drives: list[SyntheticDrive], duration_s: float) -> None:
    for sd in progress.each(drives, "recording", lambda sd: sd.name, "drives"):
        _write_npz(out / f"{sd.name}.npz", record(sd, duration_s))
    text = io.StringIO()
    w = csv.writer(text, lineterminator="\n")
    w.writerow(["drive", "path"])
    for sd in drives:
        w.writerow([sd.name, f"{sd.name}.npz"])
    atomic_write(out / "manifest.csv", lambda tmp: Path(tmp).write_text(text.getvalue()))
    truth = {sd.name: {"defect": sd.defect, "size": sd.size, "seed": sd.seed, "drive": sd.drive} for sd in drives}
    write_json(out / "truth.json", {"duration_s": duration_s, "spread": SPREAD, "drives": truth})


__all__ = ["DEFECTS", "SPREAD", "SyntheticDrive", "record", "synthetic_drives", "write_fleet"]

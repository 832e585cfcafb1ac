"""The two designs the benchmark evaluation compares, for a benchmark version.

* :func:`reference`: the benchmark's own PID + notches (:func:`servo.design.nss_reference`);
* :func:`own`: (version 2) this project's :func:`servo.design.track_following` design for the
  benchmark's plant (parameters in :data:`OWN`, chosen as ``docs/hdd.md`` explains).
"""
from __future__ import annotations

from servo.design import Design, nss_reference, track_following
from servo.hdd.benchmark import benchmark

#: Parameters of the project's design per benchmark version (track_following keywords).
#: Version 2: peak filters at the spindle's first three harmonics (the repeatable runout;
#: narrow, zero phase: T is near 1 there) and one wide peak at 850 Hz with 30 deg of phase
#: lead (phase-stable against T's lag near the crossover) that lowers the sensitivity over
#: the disk-flutter band 750-1230 Hz; notches at the modes, the 12.3 kHz one 30 dB deep.
OWN = {
    2: dict(crossover_hz=950.0, phase_margin_deg=52.0, integrator_ratio=12.0,
            notches=((4100.0, 15.0, 0.4), (5000.0, 10.0, 0.3), (7000.0, 20.0, 0.4), (12300.0, 30.0, 0.4)),
            peaks=((120.0, 20.0, 0.01, 0.0), (240.0, 12.0, 0.01, 0.0), (360.0, 6.0, 0.01, 0.0), (850.0, 2.0, 0.5, 30.0)),
            lowpass_hz=None, method="bilinear"),
}  # fmt: skip


def reference(version: int = 2) -> Design:
    """The benchmark's reference design at its PES rate, notches at twice it."""
    return nss_reference(1.0 / benchmark(version).Ts)


def own(version: int = 2, **overrides) -> Design:
    """The project's track-following design for ``version`` (``overrides`` change :data:`OWN`)."""
    b = benchmark(version)
    if version not in OWN:
        raise ValueError(f"no tuned track-following design for benchmark version {version} (only {sorted(OWN)})")
    kw = dict(OWN[version], **overrides)
    return track_following(b.J, 2.0 / b.Ts, pes_every=2, delay_s=b.Td, **kw)

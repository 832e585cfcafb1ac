"""The two designs the benchmark evaluation compares, for a benchmark version.

* :func:`reference`: the benchmark's own PID + notches (:func:`servo.design.nss_reference`);
* :func:`own`: (version 2) this project's :func:`servo.design.track_following` design for the
  benchmark's plant (parameters in :data:`OWN`, chosen as ``docs/hdd.md`` explains).
"""
from __future__ import annotations

from servo.design import Design, nss_reference, track_following
from servo.hdd.benchmark import benchmark

#: Parameters of the project's design per benchmark version (track_following keywords).
OWN = {
    2: dict(crossover_hz=950.0, phase_margin_deg=47.0, integrator_ratio=8.0,
            notches=((4100.0, 15.0, 0.4), (5000.0, 10.0, 0.3), (7000.0, 20.0, 0.4), (12300.0, 20.0, 0.4)),
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

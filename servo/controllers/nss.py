"""The NSS HDD servo benchmark's own reference design, as a controller kind ("nss").

A discrete PID on the PES at the PES rate, ``C(z) = [P(1 - z^-1) + I + D(1 - z^-1)^2] /
(1 - z^-1) / g`` (PES in tracks, current in A), then notch filters at twice the PES rate
(:func:`servo.design.nss_reference`; the benchmark in ``docs/hdd.md``).  It runs on the
two-rate cascade kernels of :mod:`servo.controllers.track`.
"""
from __future__ import annotations

from dataclasses import dataclass

from servo.fields import P
from servo.controllers.track import TwoRate
from servo.errors import ConfigError


@dataclass
class NSSSection:
    """The NSS benchmark's reference design (kind "nss"): discrete PID at the PES rate
    (PES in tracks), notches at twice the PES rate (run.sample_rate_hz = 2 / Ts)."""

    # The defaults are the benchmark's own design (example1/followdemo.m): the notches are
    # servo.design.reference.NSS_NOTCHES, written out so that loading a config does not
    # import the design tools; tests/test_nss_reference.py holds the two equal and
    # rebuilds the benchmark's matrices from the package's file.

    p_gain: float = P(2.0, "-", "the benchmark's P (PES in tracks)", 0.0)
    i_gain: float = P(0.05, "-", "the benchmark's I (per PES sample)", 0.0)
    d_gain: float = P(70.0, "-", "the benchmark's D", 0.0)
    g: float = P(1.665e3, "-", "scale: current = C / g", 0.0, None, lo_open=True)
    track_pitch: float = P(2.54e-7, "m", "track pitch (PES in tracks = e / pitch)", 0.0, None, lo_open=True)
    notch_hz: list = P([4100.0, 5000.0, 8200.0, 12300.0], "Hz", "notch centres", 0.0, None, lo_open=True)
    notch_depth_db: list = P([10.0, 20.0, 20.0, 20.0], "dB", "notch depths (the benchmark's)", 0.0, 80.0, lo_open=True)
    notch_width: list = P([0.412, 0.272, 0.724, 0.606], "-", "notch relative widths (the benchmark's)", 0.0, 2.0,
                          lo_open=True)
    pes_every: int = P(2, "ticks", "ticks per PES sample (the benchmark: 2)", 1, 2)
    output_limit: float = P(1.0, "A", "output limit of the loop", 0.0, None, lo_open=True)


class NSS(TwoRate):
    name = "nss"
    summary = "the NSS HDD benchmark's reference design: discrete PID + notches at twice the PES rate"
    Section = NSSSection

    @classmethod
    def design(cls, s: NSSSection, cfg):
        from servo.design import nss_reference

        return nss_reference(
            cfg.run.sample_rate_hz / s.pes_every, Tp=s.track_pitch, P=s.p_gain, I=s.i_gain, D=s.d_gain, g=s.g,
            notch_hz=tuple(s.notch_hz), notch_depth_db=tuple(s.notch_depth_db), notch_width=tuple(s.notch_width),
            pes_every=s.pes_every,
        )  # fmt: skip

    @classmethod
    def check(cls, s: NSSSection, cfg) -> None:
        if not (len(s.notch_hz) == len(s.notch_depth_db) == len(s.notch_width)):
            raise ConfigError("config: controller.nss.notch_hz, notch_depth_db and notch_width must have the same length")
        nyquist = cfg.run.sample_rate_hz / 2
        for i, f in enumerate(s.notch_hz):
            if f >= nyquist:
                raise ConfigError(f"config: controller.nss.notch_hz[{i}] = {f!r} is at or above Nyquist ({nyquist:g} Hz)")
        cls.params(s, cfg)  # a design the numbers do not allow is a config error

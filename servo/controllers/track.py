"""Track following: a lead-lag with an integrator, peak filters, notches at the flexible
modes and a low-pass, designed in continuous time on the double integrator and run as two compiled
cascades of second-order sections (:mod:`kernels.biquad`).

    every pes_every ticks:  e = r_base + r - x        the position error signal (PES), m
                            y = slow(e)               lead-lag + integrator, peaks, at the PES rate
    every tick:             u_n = u0 + fast(y) + u_exc   notches + low-pass, at the tick rate

``u0`` is the current applied when the loop took over (a bumpless start: the cascades start
at rest and the integrator absorbs the offset).  ``u_n`` is clamped to the output limit
and the room the stage leaves; anti-windup freezes the slow cascade's states at a PES
sample when the previous output was clamped and the error pushes further into the limit
(conditional integration, one tick late).  The paper's claim, made measurable: designed
on ``J*x'' = u_n``, the loop keeps its crossover and margins at every current level when
the compensator stage cancels the pivot (``docs/controllers.md``).

The design (:func:`servo.design.track_following`: the lead ratio and gain solved on the
exact discrete loop, discretised with scipy.signal) happens once, in :meth:`Track.params`.
:class:`TwoRate` holds what the track-following kinds share (the NSS benchmark's reference
design, ``servo/controllers/nss.py``, is the same kernel with another design).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import float64, from_dtype, void

from kernels._cache import kernel
from kernels.biquad import MAX_SECTIONS, sos_cascade, sos_cascade_try, sos_commit
from servo.fields import P
from servo.controllers.base import ControllerKind
from servo.errors import ConfigError

PARAMS = np.dtype(
    [
        ("pes_every", "f8"),  # ticks per PES sample (1 or 2)
        ("n_slow", "f8"),  # sections in use in sos_slow
        ("n_fast", "f8"),  # sections in use in sos_fast
        ("u_n_max", "f8"),  # output limit, A
        ("sos_slow", "f8", (MAX_SECTIONS, 6)),  # e (m) -> y (A), at the PES rate
        ("sos_fast", "f8", (MAX_SECTIONS, 6)),  # y (A) -> u_n (A), at the tick rate
    ]
)
STATE = np.dtype(
    [
        ("phase", "f8"),  # ticks since the latest PES sample
        ("u0", "f8"),  # current at take-over, A
        ("pes", "f8"),  # the latest PES sample, m
        ("y", "f8"),  # slow cascade output held between PES samples, A
        ("sat", "f8"),  # the previous output: +1 clamped high, -1 low, 0 free
        ("z_slow", "f8", (MAX_SECTIONS, 2)),
        ("z_try", "f8", (MAX_SECTIONS, 2)),
        ("z_fast", "f8", (MAX_SECTIONS, 2)),
    ]
)
_c_t, _p_t = from_dtype(STATE), from_dtype(PARAMS)


@kernel(void(_c_t, _p_t, float64, float64, float64), helper=True)
def two_rate_start(c, p, x, v, u_n):
    """Cascades at rest; the output starts at ``u_n`` (A)."""
    c.phase = 0.0
    c.u0 = u_n
    c.pes = 0.0
    c.y = 0.0
    c.sat = 0.0
    for i in range(MAX_SECTIONS):
        for j in range(2):
            c.z_slow[i, j] = 0.0
            c.z_try[i, j] = 0.0
            c.z_fast[i, j] = 0.0


@kernel(float64(_c_t, _p_t, float64, float64, float64, float64, float64, float64, float64), helper=True)
def two_rate_tick(c, p, x, v, r_base, r, u_exc, lo, hi):
    """One tick; returns ``u_n`` (A)."""
    if c.phase == 0.0:
        e = (r_base + r) - x
        c.pes = e
        y = sos_cascade_try(p.sos_slow, c.z_slow, c.z_try, int(p.n_slow), e)
        if not ((c.sat > 0.0 and e > 0.0) or (c.sat < 0.0 and e < 0.0)):
            sos_commit(c.z_slow, c.z_try, int(p.n_slow))
        c.y = y
    c.phase += 1.0
    if c.phase >= p.pes_every:
        c.phase = 0.0
    u = c.u0 + sos_cascade(p.sos_fast, c.z_fast, int(p.n_fast), c.y) + u_exc
    lo = max(lo, -p.u_n_max)
    hi = min(hi, p.u_n_max)
    if u > hi:
        u = hi
        c.sat = 1.0
    elif u < lo:
        u = lo
        c.sat = -1.0
    else:
        c.sat = 0.0
    return u


@kernel(void(float64[::1], _c_t), helper=True)
def two_rate_log(out, c):
    """``pes``: the latest PES sample (m)."""
    out[0] = c.pes


_DESIGNS: dict = {}


class TwoRate(ControllerKind):
    """What the two-rate cascade kinds share: records, kernels, log, and the parameter
    record and response of a :class:`servo.design.Design` (:meth:`design`)."""

    STATE, PARAMS = STATE, PARAMS
    start, tick, log = staticmethod(two_rate_start), staticmethod(two_rate_tick), staticmethod(two_rate_log)
    log_columns = ("pes",)
    log_units = {"pes": "m"}

    @classmethod
    def design(cls, section, cfg):
        """The :class:`servo.design.Design` of ``section`` at the rate of ``cfg``."""
        raise NotImplementedError

    @classmethod
    def designed(cls, section, cfg):
        """:meth:`design`, computed once per section and rate (solving it takes ~1 s)."""
        key = (cls.name, repr(section), cfg.run.sample_rate_hz)
        if key not in _DESIGNS:
            _DESIGNS[key] = cls.design(section, cfg)
        return _DESIGNS[key]

    @classmethod
    def params(cls, section, cfg) -> np.ndarray:
        try:
            d = cls.designed(section, cfg)
        except ValueError as exc:  # a design the numbers do not allow: one line, naming the section
            raise ConfigError(f"config: controller.{cls.name}: {exc}") from None
        p = np.zeros(1, PARAMS)
        p["pes_every"] = d.pes_every
        p["n_slow"], p["n_fast"] = len(d.slow_sos), len(d.fast_sos)
        p["u_n_max"] = section.output_limit
        p["sos_slow"][0, : len(d.slow_sos)] = d.slow_sos
        p["sos_fast"][0, : len(d.fast_sos)] = d.fast_sos
        return p

    @classmethod
    def response(cls, section, cfg, f_hz) -> np.ndarray:
        """The design's ``slow * hold * fast`` (:meth:`servo.design.Design.response`)."""
        return cls.designed(section, cfg).response(f_hz)

    @classmethod
    def to_control(cls, section, cfg):
        """``slow(z^N) * hold(z) * fast(z)`` at the tick period, ``N = pes_every``: the
        slow cascade with its delays stretched to ``N`` ticks, the hold's
        ``(1/N) sum_{k<N} z^-k``, the fast cascade (:meth:`response`, exactly; with
        ``N = 2`` the images the hold makes are left out, as there)."""
        import control
        from scipy import signal

        from servo.design.loop import cascade_ss, series

        d = cls.designed(section, cfg)
        n = d.pes_every
        out = cascade_ss(np.zeros((0, 6)))
        for row in np.asarray(d.slow_sos).reshape(-1, 6):
            b, a = np.zeros(2 * n + 1), np.zeros(2 * n + 1)
            b[::n], a[::n] = row[:3], row[3:]
            out = series(out, tuple(np.atleast_2d(m) for m in signal.tf2ss(b, a)))
        if n > 1:
            out = series(out, tuple(np.atleast_2d(m) for m in signal.tf2ss(np.full(n, 1.0 / n), np.eye(1, n, 0)[0])))
        out = series(out, cascade_ss(d.fast_sos))
        return control.ss(*out, cfg.dt)


@dataclass
class TrackSection:
    """Track following (kind "track"): lead-lag with an integrator, peak filters, notches, a low-pass,
    designed on the double integrator J*x'' = u_n and solved on the exact discrete loop."""

    inertia: float = P(1.0e-3, "A*s^2/m", "J of the plant the design assumes (the compensated drive)", 0.0, None, lo_open=True)
    crossover_hz: float = P(800.0, "Hz", "open-loop gain crossover", 0.0, None, lo_open=True)
    phase_margin_deg: float = P(40.0, "deg", "phase margin the lead is solved for", 5.0, 85.0)
    integrator_ratio: float = P(5.0, "-", "crossover / integrator corner (0: no integrator)", 0.0)
    notch_hz: list = P([4100.0, 7000.0, 12300.0, 16400.0], "Hz", "notch centres (the drive's flexible modes)", 0.0, None, lo_open=True)
    notch_depth_db: list = P([20.0, 20.0, 20.0, 20.0], "dB", "notch depths at their centres", 0.0, 80.0, lo_open=True)
    notch_width: list = P([0.3, 0.3, 0.3, 0.3], "-", "notch relative widths", 0.0, 2.0, lo_open=True)
    peak_hz: list = P([], "Hz", "peak filter centres at the PES rate (runout harmonics, a disturbance band; [] none)",
                      0.0, None, lo_open=True)
    peak_gain_db: list = P([], "dB", "peak gains at their centres", 0.0, 80.0, lo_open=True)
    peak_width: list = P([], "-", "peak relative widths (2 zeta)", 0.0, 2.0, lo_open=True, hi_open=True)
    peak_phase_deg: list = P([], "deg", "peak phases at their centres (a phase-stable insertion: near -angle(T))",
                             -90.0, 90.0)
    lowpass_hz: float = P(0.0, "Hz", "second-order low-pass corner (0: none)", 0.0)
    pes_every: int = P(1, "ticks", "ticks per PES sample: the lead-lag runs at the tick rate / pes_every", 1, 2)
    discretisation: str = P("bilinear", "-", "bilinear (prewarped at each block's frequency) or matched poles/zeros",
                            choices=("bilinear", "matched"))  # fmt: skip
    delay_s: float = P(10e-6, "s", "input delay the design pays for (the drive's amplifier + computation)", 0.0, 1e-3)
    output_limit: float = P(1.0, "A", "output limit of the loop", 0.0, None, lo_open=True)


class Track(TwoRate):
    name = "track"
    summary = "track following: lead-lag + integrator, notches, low-pass as compiled biquads (two rates)"
    Section = TrackSection

    @classmethod
    def design(cls, s: TrackSection, cfg):
        from servo.design import track_following

        return track_following(
            s.inertia, cfg.run.sample_rate_hz, s.crossover_hz, s.phase_margin_deg,
            integrator_ratio=s.integrator_ratio or None,
            notches=list(zip(s.notch_hz, s.notch_depth_db, s.notch_width)),
            peaks=list(zip(s.peak_hz, s.peak_gain_db, s.peak_width, s.peak_phase_deg)),
            lowpass_hz=s.lowpass_hz or None, pes_every=s.pes_every, method=s.discretisation, delay_s=s.delay_s,
        )  # fmt: skip

    @classmethod
    def check(cls, s: TrackSection, cfg) -> None:
        if not (len(s.notch_hz) == len(s.notch_depth_db) == len(s.notch_width)):
            raise ConfigError("config: controller.track.notch_hz, notch_depth_db and notch_width must have the same length")
        if not (len(s.peak_hz) == len(s.peak_gain_db) == len(s.peak_width) == len(s.peak_phase_deg)):
            raise ConfigError("config: controller.track.peak_hz, peak_gain_db, peak_width and peak_phase_deg must have "
                              "the same length")  # fmt: skip
        nyquist = cfg.run.sample_rate_hz / 2  # the notches and low-pass run at the tick rate, the lead-lag slower
        for key, f, top in [("crossover_hz", s.crossover_hz, nyquist / s.pes_every), ("lowpass_hz", s.lowpass_hz, nyquist)] + \
                [(f"notch_hz[{i}]", f, nyquist) for i, f in enumerate(s.notch_hz)] + \
                [(f"peak_hz[{i}]", f, nyquist / s.pes_every) for i, f in enumerate(s.peak_hz)]:  # fmt: skip
            if f >= top:
                raise ConfigError(f"config: controller.track.{key} = {f!r} is at or above the Nyquist frequency "
                                  f"of its rate ({top:g} Hz)")  # fmt: skip
        if len(s.notch_hz) + (1 if s.lowpass_hz else 0) > MAX_SECTIONS:
            raise ConfigError(f"config: controller.track: at most {MAX_SECTIONS} notches and low-pass sections")
        if 1 + len(s.peak_hz) > MAX_SECTIONS:
            raise ConfigError(f"config: controller.track: at most {MAX_SECTIONS - 1} peak filters (the lead-lag takes "
                              "one section of the PES-rate cascade)")  # fmt: skip
        cls.params(s, cfg)  # a design the numbers do not allow is a config error, before anything is written

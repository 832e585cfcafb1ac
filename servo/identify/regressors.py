"""The regressor of the large-motion model (Gong et al. 2002, eq. 3-4) and the two ways of
getting its derivatives from a recording.

Model (3), forces in the recording's force unit (A of VCM current for a drive)::

    J*x'' + B*x' + Fc*sgn(x') + K*x + h0 = u                   (3)
    u = phi' * p,  phi = [x'', x', sgn(x'), x, 1],  p = [J, B, Fc, K, h0]   (4)

Any subset of the terms can be switched off (``K`` for a linear axis, ``h0`` when there
is no offset...); the regressor then has only the active columns, in the order of
:data:`TERMS`.

Two derivative paths build the rows ``(phi_k, y_k)``:

* :func:`paper_regression` -- the paper's: measured velocity (the LDV), acceleration by
  backward difference.  Row ``k`` (``k = 1..n-1``) is the zero-order-hold interval
  ``[t_{k-1}, t_k]``: ``x'' = (v_k - v_{k-1})/dt``, ``x'`` and ``x`` at the interval's
  middle (the mean of the two samples), and the force ``y = u_{k-1}``, the input held
  over that interval.
* :func:`robust_regression` -- inverse-dynamics identification as practised on robots
  and on the EMPS benchmark (Janot, Gautier, Brunot 2019): zero-phase Butterworth on
  position, central differences for velocity and acceleration, the first samples (filter
  and difference start-up) dropped, then every column of the regressor *and* the force
  low-pass filtered and decimated by the same zero-phase filter ("parallel filtering"),
  which leaves the linear relation (4) intact while removing the noise band.  The
  defaults of :class:`RobustSettings` are the EMPS reference script's settings expressed
  relative to the sample rate; with them the published EMPS estimates are reproduced.

Both take ``force_lag_s``: how much later than its sample instant the recorded force acts
on the mass (an amplifier or computation delay; for the robust path also the half sample of
a zero-order-held command, which the paper path's rows already account for).  The force
column is then ``u(t - force_lag_s)`` by linear interpolation.  Default 0: the recording's
force is taken as acting at its sample instant (the EMPS reference's assumption).  A
misaligned force biases ``B`` (the edges of a square wave happen at peak speed).

Both return a :class:`Regression`: plain arrays plus the settings that made them, ready
for :func:`servo.identify.least_squares.least_squares`.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import signal

from servo.errors import ServoError

#: Parameter names of model (3), in regressor order, and their units with positions in m
#: and forces in A (of VCM current, force constant 1 N/A); see :func:`units` for others.
TERMS = ("J", "B", "Fc", "K", "h0")
UNITS = {"J": "A*s^2/m", "B": "A*s/m", "Fc": "A", "K": "A/m", "h0": "A"}
#: The signal each term multiplies, for messages and plots.
COLUMN = {"J": "x''", "B": "x'", "Fc": "sgn(x')", "K": "x", "h0": "1"}


class IdentificationError(ServoError):
    """The data cannot give what was asked: a term is not excited, the regressor is rank
    deficient, the settings do not fit the recording."""


def units(force_unit: str = "A", position_unit: str = "m") -> dict[str, str]:
    """Units of the parameters when forces are in ``force_unit`` (``"N"`` for EMPS, ``"N*m"``
    for a rotary axis's torque) and positions in ``position_unit`` (``"rad"`` for a
    rotary axis): :func:`servo.io.units.substitute`."""
    from servo.io.units import substitute

    return {k: substitute(v, force_unit, position_unit) for k, v in UNITS.items()}


def parse_terms(text: str | None = None, off: str | None = None) -> tuple[str, ...]:
    """Active terms from a comma list (``"J,B,Fc,h0"``; default all of :data:`TERMS`) minus
    those in ``off`` (``"K"``).  Unknown names raise :class:`IdentificationError`."""
    on = [s.strip() for s in (text or ",".join(TERMS)).split(",") if s.strip()]
    drop = [s.strip() for s in (off or "").split(",") if s.strip()]
    for name in on + drop:
        if name not in TERMS:
            raise IdentificationError(f"unknown term {name!r} (terms of eq. 4: {', '.join(TERMS)})")
    terms = tuple(t for t in TERMS if t in on and t not in drop)
    if not terms:
        raise IdentificationError("no term left to identify")
    return terms


@dataclass(frozen=True)
class RobustSettings:
    """Settings of the inverse-dynamics (robust) derivative path.

    ``butter_order``: order of the zero-phase Butterworth low-pass on position (default
    4; ``filtfilt`` doubles it in effect).  ``cutoff_hz``: its cutoff; ``None`` means
    ``fs/10`` (EMPS: 100 Hz at 1 kHz).  ``decimate``: decimation factor of the parallel
    filter, 1 for none (default 10).  ``decimate_order``/``decimate_ripple_db``: the
    parallel low-pass, a Chebyshev type I of order 8 with 0.05 dB ripple and cutoff
    ``0.8*(fs/2)/decimate``, run zero-phase (MATLAB's and scipy's ``decimate`` filter);
    samples are kept so that the last one is (MATLAB's choice).  ``trim_start`` and
    ``trim_end``: samples dropped at each end after differentiation, before decimation
    (default 49 each: the filter and difference edge effects).  The EMPS reference script
    drops the first 49 only: :meth:`emps_reference` is that setting.
    """

    butter_order: int = 4
    cutoff_hz: float | None = None
    decimate: int = 10
    decimate_order: int = 8
    decimate_ripple_db: float = 0.05
    trim_start: int = 49
    trim_end: int = 49

    @classmethod
    def emps_reference(cls) -> "RobustSettings":
        """The EMPS reference identification's settings (Janot, Gautier, Brunot 2019):
        the defaults, but only the first 49 samples dropped."""
        return cls(trim_end=0)

    def cutoff(self, fs: float) -> float:
        """Butterworth cutoff (Hz) at sample rate ``fs`` (Hz)."""
        return fs / 10.0 if self.cutoff_hz is None else float(self.cutoff_hz)


@dataclass(frozen=True)
class Regression:
    """Rows of eq. (4) ready for least squares.

    ``terms``: active term names (columns of ``Phi``, in :data:`TERMS` order).
    ``Phi``: (m, p) regressor; ``y``: (m,) force; ``t``: (m,) time of each row (s);
    ``x``, ``v``, ``a``: (m,) position (m), velocity (m/s), acceleration (m/s^2) of each
    row *before* any parallel filtering (what the rows were built from; after
    decimation they are the samples at the kept instants); ``dt``: spacing of the rows
    (s); ``path``: ``"paper"`` or ``"robust"``; ``settings``: what made it (JSON-able).
    """

    terms: tuple[str, ...]
    Phi: np.ndarray
    y: np.ndarray
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    dt: float
    path: str
    settings: dict = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        return self.y.shape[0]

    def column(self, term: str) -> np.ndarray:
        """The regressor column of ``term`` (m,)."""
        return self.Phi[:, self.terms.index(term)]


def regressor(a: np.ndarray, v: np.ndarray, x: np.ndarray, terms=TERMS) -> np.ndarray:
    """Regressor of eq. (4), (n, len(terms)): the columns ``x'', x', sgn(x'), x, 1`` of the
    active ``terms``.  ``sgn(0) = 0`` (a sample at rest carries no friction direction)."""
    cols = {"J": a, "B": v, "Fc": np.sign(v), "K": x, "h0": np.ones_like(x)}
    return np.column_stack([np.asarray(cols[name], dtype=float) for name in terms])


def _check_inputs(t, x, u, dt):
    t, x, u = (np.asarray(z, dtype=float).ravel() for z in (t, x, u))
    if not (t.shape == x.shape == u.shape):
        raise IdentificationError(f"t, x, u must have the same length (got {t.size}, {x.size}, {u.size})")
    if not (dt > 0 and np.isfinite(dt)):
        raise IdentificationError(f"sample period must be positive, got {dt!r}")
    return t, x, u


MAX_LAG_SHARE = 0.1
"""Largest force lag, as a share of the recording's span.  A lag is an input delay
(microseconds to milliseconds); a longer one would hold the force at ``u[0]`` over much
of the recording and fit nothing (a fit of 0.0 % error was reported for 1e9 s)."""


def lag_force(t: np.ndarray, u: np.ndarray, lag_s: float) -> np.ndarray:
    """The force acting at each sample instant when the recorded one acts ``lag_s``
    seconds late: ``u(t - lag_s)``, linearly interpolated (held at ``u[0]`` before it)."""
    if lag_s == 0.0:
        return u
    if not (np.isfinite(lag_s) and lag_s >= 0.0):
        raise IdentificationError(f"force lag must be >= 0 s, got {lag_s!r}")
    span = float(t[-1] - t[0])
    if lag_s > MAX_LAG_SHARE * span:
        raise IdentificationError(f"force lag {lag_s:g} s is more than {MAX_LAG_SHARE:.0%} of the recording "
                                  f"({span:g} s): the force would be held at its first value for most of it")  # fmt: skip
    return np.interp(t - lag_s, t, u)


def paper_regression(t, x, u, v, dt: float, terms=TERMS, force_lag_s: float = 0.0) -> Regression:
    """The paper's path: measured velocity ``v`` (m/s), backward-difference acceleration.

    ``t``, ``x``, ``u``, ``v``: (n,) samples every ``dt`` s; ``u`` the force (A) applied
    from each sample to the next (zero-order hold), ``force_lag_s`` later (see module
    doc).  Returns n-1 rows.
    """
    t, x, u = _check_inputs(t, x, u, dt)
    u = lag_force(t, u, force_lag_s)
    if v is None:
        raise IdentificationError("the paper's path needs a measured velocity column v (or use --path robust)")
    v = np.asarray(v, dtype=float).ravel()
    if v.shape != x.shape:
        raise IdentificationError(f"v must have the length of x ({x.size}), got {v.size}")
    a_k = np.diff(v) / dt  # backward difference over [t_{k-1}, t_k]
    v_k = 0.5 * (v[1:] + v[:-1])
    x_k = 0.5 * (x[1:] + x[:-1])
    return Regression(
        terms=tuple(terms), Phi=regressor(a_k, v_k, x_k, terms), y=u[:-1].copy(), t=t[1:] - 0.5 * dt,
        x=x_k, v=v_k, a=a_k, dt=dt, path="paper",
        settings={"velocity": "measured", "acceleration": "backward difference", "force_lag_s": force_lag_s},
    )  # fmt: skip


def matlab_decimate(z: np.ndarray, q: int, order: int = 8, ripple_db: float = 0.05) -> np.ndarray:
    """Low-pass and keep every ``q``-th sample, as MATLAB's ``decimate(z, q)``: a Chebyshev
    type I filter (``order``, ``ripple_db``, cutoff ``0.8/q`` of Nyquist) run forwards and
    backwards (odd-reflection padding of ``3*order`` samples), keeping the samples that
    end on the last one.  ``q = 1`` returns ``z``."""
    z = np.asarray(z, dtype=float)
    if q == 1:
        return z.copy()
    sos = signal.cheby1(order, ripple_db, 0.8 / q, output="sos")
    zf = signal.sosfiltfilt(sos, z, padlen=min(3 * order, z.size - 1))
    return zf[_keep(z.size, q)]


def _keep(n: int, q: int) -> slice:
    """Indices kept by a decimation by ``q`` of ``n`` samples (the last one is kept)."""
    return slice((n - 1) % q, n, q)


def robust_regression(t, x, u, dt: float, terms=TERMS, settings: RobustSettings | None = None,
                      force_lag_s: float = 0.0) -> Regression:  # fmt: skip
    """The inverse-dynamics path: Butterworth on ``x``, central differences, parallel
    low-pass and decimation of the regressor columns and the force ``u``.

    ``t``, ``x`` (m), ``u`` (force, acting ``force_lag_s`` after its sample): (n,)
    samples every ``dt`` s.  Returns about ``(n - trim_start - trim_end)/decimate`` rows
    spaced ``decimate*dt``.
    """
    s = settings or RobustSettings()
    t, x, u = _check_inputs(t, x, u, dt)
    u = lag_force(t, u, force_lag_s)
    fs = 1.0 / dt
    fc = s.cutoff(fs)
    if s.butter_order < 1:
        raise IdentificationError(f"Butterworth order must be >= 1, got {s.butter_order}")
    if not 0.0 < fc < fs / 2:
        raise IdentificationError(f"Butterworth cutoff {fc:g} Hz must lie between 0 and Nyquist ({fs / 2:g} Hz)")
    if s.decimate < 1:
        raise IdentificationError(f"decimation factor must be >= 1, got {s.decimate}")
    if s.trim_start < 0 or s.trim_end < 0:
        raise IdentificationError("trim_start and trim_end must be >= 0")
    pad = 3 * s.butter_order  # MATLAB filtfilt: 3*(filter length - 1)
    kept = x.size - s.trim_start - s.trim_end
    if x.size <= pad or kept < 10 * s.decimate:
        raise IdentificationError(
            f"recording too short for the robust path: {x.size} samples, {kept} after trimming, "
            f"need at least {10 * s.decimate} (decimation by {s.decimate})"
        )
    b, a = signal.butter(s.butter_order, fc / (fs / 2))
    x_f = signal.filtfilt(b, a, x, padlen=pad)
    v_f = np.gradient(x_f, dt)  # central differences (one-sided at the ends)
    a_f = np.gradient(v_f, dt)
    sl = slice(s.trim_start, x.size - s.trim_end)
    Phi0 = regressor(a_f[sl], v_f[sl], x_f[sl], terms)
    keep = _keep(kept, s.decimate)
    dec = lambda z: matlab_decimate(z, s.decimate, s.decimate_order, s.decimate_ripple_db)  # noqa: E731
    Phi = np.column_stack([dec(Phi0[:, j]) for j in range(Phi0.shape[1])])
    y = dec(u[sl])
    return Regression(
        terms=tuple(terms), Phi=Phi, y=y, t=t[sl][keep], x=x_f[sl][keep], v=v_f[sl][keep], a=a_f[sl][keep],
        dt=dt * s.decimate, path="robust", settings={**asdict(s), "cutoff_hz": fc, "force_lag_s": force_lag_s},
    )  # fmt: skip


__all__ = [
    "COLUMN", "TERMS", "UNITS", "IdentificationError", "Regression", "RobustSettings", "lag_force", "matlab_decimate",
    "paper_regression", "parse_terms", "regressor", "robust_regression", "units",
]

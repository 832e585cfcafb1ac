"""The inverse-dynamics path at full rate, and the rows every fit of a diagnosis uses.

The rows are those of :func:`servo.identify.robust_regression` (zero-phase Butterworth on
position, central differences, samples trimmed at both ends, every column and the force
low-pass filtered and decimated by the same zero-phase filter), with three changes that a
diagnosis needs and an identification does not:

* **The acceleration is the three-point second difference** of the filtered position
  (:func:`second_difference`) and the force passes through the same Butterworth filter
  as the position.  For a plant driven through a zero-order hold this acceleration
  matches the aligned force exactly at every frequency; a derivative of a central
  difference (``np.gradient`` twice) is 0.5 % low at the rows' band edge, a
  frequency-dependent inertia that a diagnosis finds as a resonance on every
  simulated recording.  The velocity is a sixth-order central difference
  (:func:`derivative`).

* **The force is aligned with the acceleration.**  A recorded input ``u[k]`` is a
  zero-order hold: it acts over ``[t_k, t_k+dt]``.  The central-difference acceleration
  at ``t_k`` sees the mean force over ``[t_k-dt, t_k+dt]``, which for a held input is
  ``(u[k-1] + u[k])/2``.  Using ``u[k]`` instead is a half-sample time shift that a
  diagnosis would (rightly) report as a ``time_delay`` on every recording; on the
  simulated drive it raises the baseline's relative error from 0.6 % to 2.1 %.
* **Rows where the direction of motion is uncertain are marked.**  Where ``|x'|`` is
  within three noise standard deviations of zero the sign column ``sgn(x')`` is a coin
  toss and, if the arm sticks, the friction force is a constraint force that no model of
  the state can predict.  Such rows (and the rows whose decimation filter reaches them)
  are kept out of every fit and test (``Signals.valid``); their share is reported.

Extra regressor columns are built at full rate from the filtered signals (``xf``, ``vf``,
``af``) and the aligned force, then passed through :meth:`Signals.rows`, the same
parallel filter and decimation, so the linear relation between the force and any
column survives the filtering exactly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from scipy import signal

from servo.diagnose.scope import OutOfDomain
from servo.identify.regressors import IdentificationError, RobustSettings, regressor
from servo.io.recording import Recording

#: ``|x'|`` below this many noise standard deviations: the direction is uncertain.
DIRECTION_Z = 3.0
#: ``|vf|`` below this many times the velocity the input drives above the Butterworth
#: (:func:`driven_ripple`): the direction is uncertain (the fitted inertia's error)
RIPPLE_MARGIN = 1.5
#: the ripple rule is not applied where it would leave fewer usable rows than this share
#: (and the noise rule more).  A closed loop holding the arm between steps dithers it
#: with the sensor noise it feeds back: the true velocity reverses every few samples
#: above the Butterworth while the filtered one does not, and the rows there carry a
#: friction that switches with it, 12-28 x the floor on the development nulls.  At a
#: decimation of 3 the dither is inside the band and the ripple rule leaves 12-33 % of
#: the rows (the moves), at the floor; 20 % here refused or fell back on 3 nulls of 8
#: (docs/studies/2026-11-28-nulls-every-excitation.md)
RIPPLE_MIN_USABLE = 0.1
#: the spectrum's direction threshold is kept only where it leaves at least this share of
#: the rows the first estimate's threshold leaves (:func:`make_signals`)
THRESHOLD_KEEP = 0.9
#: the effective inputs whose sign column :meth:`Signals.sign_for` keeps (the most recent)
SIGN_CACHE = 2
#: a row is unusable if its decimation filter's response to a sample there exceeds this
#: fraction of the response's peak (the filter's reach: 15 rows with the default settings)
REACH_LEVEL = 0.01


def align(u: np.ndarray) -> np.ndarray:
    """The held force seen by a central difference at each sample: ``(u[k-1]+u[k])/2``
    (``u[0]`` for the first)."""
    out = np.empty_like(u)
    out[0] = u[0]
    out[1:] = 0.5 * (u[1:] + u[:-1])
    return out


@dataclass
class Signals:
    """Full-rate signals of one recording and the row maker.

    ``t``, ``u``, ``x``: (n,) the recording (s, force, m); ``xf``, ``vf``, ``af``: (n,)
    filtered position (m), velocity (m/s), acceleration (m/s^2); ``dt`` sample period (s);
    ``settings`` the robust path's; ``keep``: (m,) full-rate index of each row; ``valid``:
    (m,) rows usable by the fits; ``noise_x``: estimated position noise std (m, including
    quantisation); ``noise_v``: the resulting std of ``vf`` (m/s); ``v_threshold``: the
    speed below which the direction is uncertain (m/s).
    """

    t: np.ndarray
    u: np.ndarray
    x: np.ndarray
    xf: np.ndarray
    vf: np.ndarray
    af: np.ndarray
    dt: float
    settings: RobustSettings
    keep: np.ndarray
    valid: np.ndarray
    noise_x: float
    noise_v: float
    v_threshold: float
    #: the position noise's spectrum (:class:`servo.diagnose.noise.NoiseSpectrum`) that
    #: ``noise_x`` and ``noise_v`` come from; None: read from what the Butterworth removes
    noise: object = None
    #: (n,) m/s: the envelope of the velocity the input drives above the Butterworth's
    #: cutoff, which the filtered velocity lacks (:func:`driven_ripple`); None: not known
    v_ripple: np.ndarray | None = None
    #: the share of the rows clear of every sample whose direction is uncertain, the
    #: ripple rule's included, whether or not that rule was applied (:func:`make_signals`
    #: falls back to the noise rule's rows where it leaves too few); None: not measured
    signed_share: float | None = None
    #: the share of the rows clear of the noise rule's uncertain samples alone (``|vf|``
    #: within ``v_threshold``); None: not measured
    noise_share: float | None = None

    @property
    def usable_share(self) -> float:
        """The share of the rows usable *with the friction sign the arm had*: ``valid``'s,
        or, where the ripple rule fell back to the noise rule's rows, the share that
        rule would leave (the fallback's rows carry the misfit of a wrong sign, so a
        choice of decimation must not count them as usable)."""
        share = float(self.valid.mean())
        return share if self.signed_share is None else min(share, self.signed_share)

    @property
    def uncertain(self) -> np.ndarray:
        """(n,) bool: the samples whose direction of motion the filtered velocity does
        not tell: ``|vf|`` within ``v_threshold`` (the noise) or within ``v_ripple``
        (the motion the filter removed could reverse it)."""
        slow = np.abs(self.vf) <= self.v_threshold
        return slow if self.v_ripple is None else slow | (np.abs(self.vf) <= self.v_ripple)

    @property
    def n(self) -> int:
        return self.t.shape[0]

    @property
    def m(self) -> int:
        """Number of rows."""
        return self.keep.shape[0]

    @property
    def row_dt(self) -> float:
        """Spacing of the rows (s)."""
        return self.dt * self.settings.decimate

    @cached_property
    def sign_v(self) -> np.ndarray:
        """``sgn(x')`` as the rows see it (n,): :func:`held_sign` of the filtered velocity
        with its reversals placed by :func:`reversal_times` with the force that is not the
        friction's (:meth:`known_force`), whose variation near a reversal the crossing's
        fit must not read as a kink."""
        return self._placed_sign(self.force())

    def sign_for(self, u_eff: np.ndarray | None = None) -> np.ndarray:
        """:attr:`sign_v` with the reversals placed with the force of the effective input
        ``u_eff`` (n,) that reaches the arm (a model's delay or saturation,
        :meth:`servo.diagnose.model.Design.u_eff`; None or the recorded input:
        :attr:`sign_v`).  The crossing's fit takes the input's velocity out of the
        filtered velocity; with the recorded input where the arm feels it three samples
        later (the outside suite's ``delay``), every fast reversal was placed off and
        the rows there carried an impulse, the held-out residual structured against the
        distance since reversal (z 7.4 in its first bin).  The :data:`SIGN_CACHE` most
        recent inputs' signs are kept (a term's grid asks for the same one many times)."""
        if u_eff is None or u_eff is self.u:
            return self.sign_v
        return self._by_input("_signs_by_input", u_eff, lambda u: self._placed_sign(self.force(u)))

    def _by_input(self, slot: str, u_eff: np.ndarray, make) -> np.ndarray:
        """``make(u_eff)``, kept in this instance's ``slot`` for the :data:`SIGN_CACHE`
        most recent inputs, matched by identity (a model's effective input is one array
        that every column and the target ask for in turn)."""
        held = self.__dict__.setdefault(slot, [])
        for u, value in held:
            if u is u_eff:
                return value
        value = make(u_eff)
        held.append((u_eff, value))
        del held[:-SIGN_CACHE]
        return value

    def _placed_sign(self, force: np.ndarray) -> np.ndarray:
        """:func:`held_sign` of the filtered velocity, its reversals placed with the force
        that is not the friction's, ``force`` (n, through the position's Butterworth) less
        the first fit's smooth forces (:meth:`known_force`)."""
        known, J = self.known_force(force)
        t0 = reversal_times(self.vf, self.settings, 1.0 / self.dt, self.v_threshold, known, J)
        return held_sign(self.vf, t0)

    def known_force(self, force: np.ndarray | None = None) -> tuple[np.ndarray | None, float | None]:
        """The force near a reversal that is not the friction's switch (n,), and the
        inertia (F s^2/m) it drives: ``force`` (default the recorded one, through the
        position's Butterworth) less the viscous, spring and offset forces of
        :attr:`first_balance`.  ``(None, None)`` where that fit has no positive inertia.

        The viscous force counts where the speed changes fast on either side of a
        reversal: a closed loop settling after a step reverses 10-30 samples after its
        kick, where ``B*v`` changes by more than the friction's switch within the
        crossing's window and not linearly in time (the fit's cubic covers only that).
        With the input alone taken out, the crossing was placed 0.18 sample early on
        average on a closed-loop steps null (68 settling reversals, against the
        integrator's own crossings), and the rows beside every reversal left
        1.2-1.45 x the floor where the sensor's low-pass noise sets a low one; with the
        viscous force out too, 0.05 sample
        (docs/studies/2026-11-28-closed-step-nulls.md)."""
        fit = self.first_balance
        if fit is None:
            return None, None
        J, B, K, h0 = fit
        force = self.force() if force is None else force
        return force - B * self.vf - K * self.xf - h0, J

    @cached_property
    def first_balance(self) -> tuple[float, float, float, float] | None:
        """``(J, B, K, h0)`` of eq. (3) fitted once on the usable rows with the recorded
        force and the sign at the samples (:meth:`balance_fit`); None where its inertia
        is not positive.  Every input's crossings are placed with it (:meth:`sign_for`:
        the outside suite's 3-sample delay moves the inertia by 0.03 %, and a fit per
        input made the diagnosis of its hysteresis case, which tries two dozen inputs,
        23 % slower)."""
        coef = self.balance_fit(self.force(), held_sign(self.vf))
        if coef is None or not (coef[0] > 0 and np.isfinite(coef).all()):
            return None
        return tuple(float(c) for c in coef[:4])

    def inertia_estimate(self, force: np.ndarray) -> float | None:
        """The inertia (F s^2/m) of eq. (3) fitted on the usable rows with the sign at
        the samples (``J, B, K, h0, Fc``: what the crossings' fit needs to take the
        input's part out of the velocity near a reversal, :func:`reversal_times`);
        None where it is not positive or the rows are too few."""
        coef = self.balance_fit(force, held_sign(self.vf))
        if coef is None:
            return None
        J = float(coef[0])
        return J if J > 0 and np.isfinite(J) else None

    def balance_fit(self, force: np.ndarray, sign: np.ndarray) -> np.ndarray | None:
        """``(J, B, K, h0, Fc)`` of eq. (3) fitted by least squares on the usable rows,
        the Coulomb column ``sign`` (n,); None with fewer than 50 usable rows."""
        if self.valid.sum() < 50:
            return None
        Z = [self.af, self.vf, self.xf, np.ones(self.n), sign]
        A = np.column_stack([self.rows(z)[self.valid] for z in Z])
        scale = np.abs(A).max(axis=0).clip(1e-300)
        coef = np.linalg.lstsq(A / scale, self.rows(force)[self.valid], rcond=None)[0] / scale
        return coef[[0, 1, 2, 3, 4]]

    @cached_property
    def t_rows(self) -> np.ndarray:
        return self.t[self.keep]

    @cached_property
    def x_rows(self) -> np.ndarray:
        return self.xf[self.keep]

    @cached_property
    def v_rows(self) -> np.ndarray:
        return self.vf[self.keep]

    def rows(self, z: np.ndarray) -> np.ndarray:
        """The rows of a full-rate signal ``z`` (n,): trimmed, parallel-filtered and
        decimated exactly as the regressor columns and the force.

        The result is compact (:func:`decimate`): a view of the filtered full-rate
        column would keep all ``n`` samples alive for as long as the rows are cached
        (the diagnosis caches hundreds)."""
        s = self.settings
        return decimate(z[s.trim_start : self.n - s.trim_end], s.decimate, s.decimate_order, s.decimate_ripple_db)

    def force(self, u_eff: np.ndarray | None = None) -> np.ndarray:
        """The force at full rate as the rows see it (n,): aligned with the acceleration
        and passed through the position's Butterworth filter (parallel filtering: the
        acceleration is a difference of the filtered position, so the force must be
        filtered alike for ``J*x'' = u`` to hold exactly).  The recorded input's
        (``u_eff`` None or the recording's own ``u``) is filtered once and shared, read-only
        (:attr:`recorded_force`); the :data:`SIGN_CACHE` most recent other inputs' are kept
        (the target, the sign column and the input-reading terms ask for the same one).
        Callers must not write into the result."""
        if u_eff is None or u_eff is self.u:
            return self.recorded_force
        return self._by_input("_forces_by_input", u_eff, lambda u: self.butter(align(u)))

    @cached_property
    def recorded_force(self) -> np.ndarray:
        """:meth:`force` of the recorded input (n,), read-only: the signals, the sign, the
        ripple, the baseline's target and the input terms' columns all ask for it (13
        full-rate Butterworth passes of the same input at 1e6 samples before it was kept)."""
        f = self.butter(align(self.u))
        f.setflags(write=False)
        return f

    def butter(self, z: np.ndarray) -> np.ndarray:
        """``z`` through the zero-phase Butterworth applied to the position."""
        fs = 1.0 / self.dt
        b, a = butter_ba(self.settings.butter_order, self.settings.cutoff(fs) / (fs / 2))
        return signal.filtfilt(b, a, z, padlen=3 * self.settings.butter_order)

    def force_rows(self, u_eff: np.ndarray | None = None) -> np.ndarray:
        """Rows of the force (default: the recorded input)."""
        return self.rows(self.force(u_eff))

    def base_columns(self, terms) -> np.ndarray:
        """Rows of the regressor of eq. (4) for ``terms`` (as ``robust_regression``)."""
        Phi0 = regressor(self.af, self.vf, self.xf, terms)
        return np.column_stack([self.rows(Phi0[:, j]) for j in range(Phi0.shape[1])])


@lru_cache(maxsize=16)
def butter_ba(order: int, wn: float) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.butter(order, wn)``, designed once per (order, cutoff): a diagnosis
    filters a hundred columns with the same filter, and each design took 2 ms."""
    return signal.butter(order, wn)


@lru_cache(maxsize=16)
def cheby_sos(order: int, ripple_db: float, q: int) -> np.ndarray:
    """The decimation filter of :func:`servo.identify.regressors.matlab_decimate`
    (Chebyshev type I, cutoff ``0.8/q`` of Nyquist, second-order sections), designed once."""
    return signal.cheby1(order, ripple_db, 0.8 / q, output="sos")


@lru_cache(maxsize=16)
def cheby_zi(order: int, ripple_db: float, q: int) -> np.ndarray:
    """``scipy.signal.sosfilt_zi`` of :func:`cheby_sos` ((sections, 2), C order), computed once."""
    return np.ascontiguousarray(signal.sosfilt_zi(cheby_sos(order, ripple_db, q)))


def decimate(z: np.ndarray, q: int, order: int = 8, ripple_db: float = 0.05) -> np.ndarray:
    """:func:`servo.identify.regressors.matlab_decimate` with the filter designed once
    (:func:`cheby_sos`): the same operations, the same result, ``(ceil(n/q),)`` for
    ``z`` (n,), a compact array (not a view of the filtered ``n`` samples).

    A column longer than the filter's padding goes through
    :func:`kernels.decimate.filtfilt_decimate` (scipy's ``sosfiltfilt`` arithmetic to
    the bit, without its four full-length temporaries: 14 ms instead of 22 ms at 1e6
    samples); a shorter one through ``sosfiltfilt``, which says why it cannot."""
    z = np.asarray(z, dtype=float)
    if q == 1:
        return z.copy()
    pad = min(3 * order, z.size - 1)
    if z.ndim == 1 and 0 < pad < z.size:
        from kernels.decimate import filtfilt_decimate

        out = np.empty(-(-z.size // q))
        filtfilt_decimate(cheby_sos(order, ripple_db, q), cheby_zi(order, ripple_db, q), np.ascontiguousarray(z), pad,
                          q, np.empty(z.size + 2 * pad), out)  # fmt: skip
        return out
    zf = signal.sosfiltfilt(cheby_sos(order, ripple_db, q), z, padlen=pad)
    return np.array(zf[slice((z.size - 1) % q, z.size, q)], copy=True, order="C")


#: sixth-order central difference, f'(t) = sum(c_j*f(t + j*dt))/dt for j = -3..3
STENCIL = np.array([-1.0, 9.0, -45.0, 0.0, 45.0, -9.0, 1.0]) / 60.0


def derivative(z: np.ndarray, dt: float) -> np.ndarray:
    """``dz/dt`` by a sixth-order central difference (second-order ``np.gradient`` in the
    three samples at each end, which the rows trim away).  Its gain is
    ``1 - (w*dt)^6/140``: exact within 2e-6 at the rows' band edge (``w*dt`` = 0.25 for
    decimation by 10), where a plain central difference is 1 % low per derivative
    (``1 - (w*dt)^2/6``), a frequency-dependent error that a diagnosis would find as a
    spurious resonance on every recording."""
    out = np.gradient(z, dt)
    if z.size > 7:
        out[3:-3] = np.convolve(z, STENCIL[::-1], mode="valid") / dt
    return out


def second_difference(z: np.ndarray, dt: float) -> np.ndarray:
    """``(z[k+1] - 2 z[k] + z[k-1])/dt^2`` (the end samples copy their neighbours).

    For a plant driven through a zero-order hold this is the acceleration that matches
    the aligned force exactly, at every frequency: for a double integrator
    ``J*x'' = u`` sampled under a held ``u`` it equals ``(u[k-1] + u[k])/(2*J)`` to
    rounding.  Any other estimate (a derivative of a derivative, spectral, higher order)
    differs from it by a frequency-dependent factor (``1 + (w*dt)^2/12`` for an exact
    second derivative) that a diagnosis would report as a resonance or a delay."""
    out = np.empty_like(z)
    out[1:-1] = (z[2:] - 2.0 * z[1:-1] + z[:-2]) / (dt * dt)
    out[0], out[-1] = out[1], out[-2]
    return out


def held_sign(v: np.ndarray, crossings: np.ndarray | None = None) -> np.ndarray:
    """``sgn(v)`` averaged as the acceleration averages the motion (n,).

    The three-point second difference at sample ``k`` is the average of the true
    acceleration over ``[t_k - dt, t_k + dt]`` with the triangular weight
    ``(dt - |s|)/dt^2`` (and the aligned force the same average of the held input), so
    the force balance at ``k`` holds for the same average of every force.  A Coulomb
    force ``Fc*sgn(v)`` switches at the velocity's zero crossing, which lies between two
    samples: taking the sign at the sample instead moves the switch by up to half a
    sample, a force impulse of up to ``Fc*dt`` at every reversal.  Each sign change of
    ``v`` between samples ``k`` and ``k+1`` is placed at ``crossings`` (fractional
    sample positions, one per sign change; default: linear interpolation of ``v``) and
    the triangular average of the sign around the samples near it is exact for it."""
    out = np.sign(v).astype(float)
    n = v.size
    if n < 3:
        return out
    cross = np.flatnonzero(np.sign(v[1:]) * np.sign(v[:-1]) < 0)  # between k and k+1
    if cross.size == 0:
        return out
    t0 = cross + v[cross] / (v[cross] - v[cross + 1]) if crossings is None else np.asarray(crossings, float)
    before, after = np.sign(v[cross]), np.sign(v[cross + 1])
    # a crossing placed away from where v changes sign moves the samples between the two
    # to the side of the placed one: every sample from the one before the earlier of the
    # two to the one after the later, and none past a neighbouring sign change of v
    lo = np.minimum(np.floor(t0).astype(int) - 1, cross)
    hi = np.maximum(np.floor(t0).astype(int) + 2, cross + 1)
    prev = np.concatenate([[-1], cross[:-1]])  # the neighbouring sign changes
    nxt = np.concatenate([cross[1:] + 1, [n]])
    lo, hi = np.maximum(lo, prev + 1), np.minimum(hi, nxt - 1)
    for off in range(int((hi - lo).max(initial=0)) + 1):
        idx = lo + off
        pos = np.clip(t0 - idx, -1.0, 1.0)  # the crossing relative to the sample, in samples
        ok = (idx <= hi) & (idx >= 0) & (idx < n)
        W = np.where(pos <= 0, 0.5 * (1 + pos) ** 2, 1 - 0.5 * (1 - pos) ** 2)  # weight before the crossing
        out[idx[ok]] = (before * W + after * (1 - W))[ok]
    # two crossings within two samples of each other: the sign at the sample (a crossing
    # that close is noise, and those rows are not usable anyway)
    for j in np.flatnonzero(np.diff(cross) <= 2):
        a, b = max(cross[j] - 1, 0), min(cross[j + 1] + 3, n)
        out[a:b] = np.sign(v[a:b])
    return out


#: the zero crossing of the velocity is fitted over this many samples either side
KINK_HALF_WIDTH = 20
#: a kink is fitted only where it leaves this many times less of the filtered velocity
#: unexplained than a smooth motion does
KINK_EVIDENCE = 10.0
#: candidate crossing positions (samples from the sample before the filtered crossing)
KINK_GRID = np.linspace(-2.0, 1.0, 121)


@lru_cache(maxsize=8)
def _kink_projectors(order: int, wn: float, half: int, cubic: bool = False) -> np.ndarray:
    """``I - Q Q'`` (F, 2*half+1, 2*half+1) per candidate crossing offset of
    :data:`KINK_GRID`: the projection off the velocity, through the path's filter and
    derivative, of a motion whose velocity is zero at that offset and whose
    acceleration jumps there (a kinked parabola in position) plus a constant; with
    ``cubic``, an acceleration changing linearly in time too (the viscous and spring
    forces across a fast reversal, once the input's own part is a column)."""
    b, a = signal.butter(order, wn)
    N = 8 * half + 201
    tt = np.arange(N) - N // 2
    j = np.arange(-half, half + 1) + N // 2

    def pipe(z):
        return derivative(signal.filtfilt(b, a, z, padlen=3 * order), 1.0)[j]

    out = []
    for phi in KINK_GRID:
        tau = tt - phi
        B = np.column_stack([pipe(np.where(tau < 0, tau * tau / 2, 0.0)), pipe(np.where(tau > 0, tau * tau / 2, 0.0)),
                             np.ones(j.size)] + ([pipe(tt**3 / 6.0)] if cubic else []))  # fmt: skip
        Q, _ = np.linalg.qr(B)
        out.append(np.eye(j.size) - Q @ Q.T)
    # the same without a kink (a smooth motion: quadratic and cubic in time, and a constant)
    B = np.column_stack([pipe(tt * tt / 2.0), pipe(tt**3 / 6.0), np.ones(j.size)])
    Q, _ = np.linalg.qr(B)
    out.append(np.eye(j.size) - Q @ Q.T)
    return np.array(out)


def force_velocity(force: np.ndarray, centres: np.ndarray, half: int) -> np.ndarray:
    """(c, 2*half+1) the velocity a unit mass would gain from ``force`` (the force through
    the position's Butterworth, full rate) over ``centres[i] +- half`` samples, through
    the rows' derivative, up to a constant per window: the position ``P`` whose second
    difference is the force (:func:`second_difference`, exact for a held input),
    differentiated by :func:`derivative`.  In samples (``dt = 1``); the scale is free."""
    k = np.arange(-half - 3, half + 4)  # the stencil needs 3 samples either side
    f = force[centres[:, None] + k[None, :]]
    P = np.zeros_like(f)
    P[:, 2:] = np.cumsum(np.cumsum(f[:, 1:-1], axis=1), axis=1)  # P[k+1] - 2P[k] + P[k-1] = f[k]
    return sum(STENCIL[j] * P[:, j : j + P.shape[1] - 6] for j in range(7))  # v at k[3:-3] = -half..half


def reversal_times(vf: np.ndarray, settings, fs: float, fast: float, force: np.ndarray | None = None,
                   inertia: float | None = None) -> np.ndarray:
    """Fractional sample position of every sign change of the filtered velocity ``vf``.

    A friction force that flips at a reversal makes the acceleration jump there, and
    the zero-phase filter spreads that kink: the filtered velocity crosses zero late
    (0.2-0.9 sample on the proving ground's fast reversals, always on the same side),
    which left a residual at every reversal that a hysteresis term partly fitted
    (proving-ground nulls 1.5-1.8 x their noise floor; with the true crossing times,
    1.0-1.1).  Where ``|vf|`` exceeds ``fast`` on both sides (a reversal whose rows
    are used), the crossing is fitted: the filtered velocity of a kinked motion,
    over :data:`KINK_HALF_WIDTH` samples either side, for each candidate position;
    elsewhere, and when the best candidate is at the edge of the grid, linear
    interpolation of ``vf``.

    ``force`` (n,), the force that is not the friction's, through the position's
    Butterworth (:meth:`Signals.known_force`: the recorded one less the viscous, spring
    and offset forces of a first fit), and ``inertia`` (F s^2/m, the same fit's):
    the velocity the force drives in that inertia (:func:`force_velocity`) is taken out
    of the filtered velocity before the kinked and the smooth motion are fitted: the
    input changes the acceleration near a reversal too (a multisine, an open loop's
    feedforward), and a kinked parabola alone then put the kink up to 1.3 samples
    from the friction's switch, where the force balance put it
    (docs/studies/2026-11-24-reversal-crossings.md); the rows kept at those fast reversals carried up to 30 x their noise
    floor, and the verdict was ``unexplained`` on nulls.  With the force, the kinked
    motion's acceleration may also change linearly in time (the viscous force across
    a reversal whose speed changes fast: a chirp's fast end, where without it the
    kink was placed up to 0.9 sample off).  The inertia is the rows' fit, not a free
    scale per reversal: a free scale and that slope traded off against the kink's
    place (0.5 sample off on a multisine)."""
    v = vf
    n = v.size
    cross = np.flatnonzero(np.sign(v[1:]) * np.sign(v[:-1]) < 0)
    t0 = cross + v[cross] / (v[cross] - v[cross + 1])
    h = KINK_HALF_WIDTH
    ok = (cross >= h + 4) & (cross + h + 5 < n)
    ok[ok] &= (np.abs(v[cross[ok] - 1]) > fast) & (np.abs(v[cross[ok] + 2]) > fast)
    if not ok.any():
        return t0
    known = force is not None and inertia is not None and inertia > 0
    R = _kink_projectors(int(settings.butter_order), float(settings.cutoff(fs) / (fs / 2)), h, known)
    idx = np.flatnonzero(ok)
    Y = np.stack([v[cross[i] - h : cross[i] + h + 1] for i in idx])  # (c, 2h+1)
    if known:  # the velocity the input drives, x = P*dt^2/J: vf = derivative(P)*dt/J
        Y = Y - force_velocity(np.asarray(force, dtype=float), cross[idx], h) / (fs * inertia)
    Ry = np.einsum("fij,cj->cfi", R, Y)
    e = np.einsum("cfi,cfi->cf", Ry, Ry)
    smooth, e = e[:, -1], e[:, :-1]
    best = e.argmin(axis=1)
    # only a kink that explains the filtered velocity far better than a smooth motion is
    # placed by the fit (a white-noise input makes the acceleration rough everywhere)
    inner = (best > 0) & (best < KINK_GRID.size - 1) & (e.min(axis=1) * KINK_EVIDENCE < smooth)
    step = KINK_GRID[1] - KINK_GRID[0]
    for c, i in enumerate(idx):
        if not inner[c]:
            continue
        f = best[c]
        den = e[c, f - 1] - 2 * e[c, f] + e[c, f + 1]
        d = 0.5 * (e[c, f - 1] - e[c, f + 1]) / den if den > 0 else 0.0
        t0[i] = cross[i] + KINK_GRID[f] + float(np.clip(d, -1, 1)) * step
    return t0


def velocity_noise_gain(settings: RobustSettings, fs: float) -> float:
    """``std(vf)/std(x)`` for white position noise: the 2-norm of the impulse response of
    Butterworth (zero-phase) followed by a central difference, in 1/s."""
    b, a = signal.butter(settings.butter_order, settings.cutoff(fs) / (fs / 2))
    imp = np.zeros(801)
    imp[400] = 1.0
    h = derivative(signal.filtfilt(b, a, imp, padlen=3 * settings.butter_order), 1.0 / fs)
    return float(np.linalg.norm(h))


def filter_reach(settings: RobustSettings, level: float = REACH_LEVEL) -> int:
    """Samples (full rate) over which the rows' decimation filter spreads one sample:
    the extent of its response above ``level`` (default :data:`REACH_LEVEL`) of the peak."""
    q = settings.decimate
    if q == 1:
        return 2
    n = 400 * q + 1
    worst = 0
    for off in range(q):
        z = np.zeros(n)
        z[n // 2 + off] = 1.0
        r = np.abs(decimate(z, q, settings.decimate_order, settings.decimate_ripple_db))
        big = np.flatnonzero(r > level * r.max())
        worst = max(worst, (big.max() - big.min()) // 2 + 1)
    return int(worst * q)


def make_signals(rec: Recording, settings: RobustSettings | None = None) -> Signals:
    """Filter and differentiate ``rec`` at full rate and place the rows (see module doc).

    Raises :class:`IdentificationError` when the settings do not fit the recording."""
    s = settings or RobustSettings()
    t, x, u = (np.ascontiguousarray(z, dtype=float) for z in (rec.t, rec.x, rec.u))
    dt = rec.dt
    fs = 1.0 / dt
    fc = s.cutoff(fs)
    if not 0.0 < fc < fs / 2:
        raise IdentificationError(f"Butterworth cutoff {fc:g} Hz must lie between 0 and Nyquist ({fs / 2:g} Hz)")
    if s.decimate < 1 or s.butter_order < 1:
        raise IdentificationError("the decimation factor and the Butterworth order must be >= 1")
    n = x.size
    kept = n - s.trim_start - s.trim_end
    if n <= 3 * s.butter_order or kept < 200 * s.decimate:
        raise OutOfDomain(
            f"recording too short to diagnose: {n} samples, {kept} after trimming; need at least "
            f"{200 * s.decimate} (200 rows after decimation by {s.decimate})"
        )
    b, a = signal.butter(s.butter_order, fc / (fs / 2))
    xf = np.ascontiguousarray(signal.filtfilt(b, a, x, padlen=3 * s.butter_order))
    vf = derivative(xf, dt)
    af = second_difference(xf, dt)
    keep = np.arange(s.trim_start, n - s.trim_end)[(kept - 1) % s.decimate :: s.decimate]

    # a first position noise: what the Butterworth removes (a robust std: kinks and steps
    # of the motion leave a few large values), scaled up for the part of the band it
    # keeps; it places the rows whose direction is certain for the force balance that
    # reads the noise where the input drives nothing the balance misses (servo.diagnose.noise)
    frac_kept = min(fc / (fs / 2), 0.5)
    hp = (x - xf)[s.trim_start : n - s.trim_end]
    noise_x = float(1.4826 * np.median(np.abs(hp - np.median(hp))) / np.sqrt(1.0 - frac_kept))
    noise_v = noise_x * velocity_noise_gain(s, fs)
    v_thr = DIRECTION_Z * noise_v
    # a row is unusable if its decimation filter reaches an uncertain sample
    reach = filter_reach(s)
    valid = rows_clear_of(keep, np.abs(vf) <= v_thr, reach)
    sig = Signals(t, u, x, xf, vf, af, dt, s, keep, valid, noise_x, noise_v, v_thr)
    coef = balance_coefficients(sig)
    if coef is None:
        return sig
    spec = sensor_noise(sig, coef)
    if spec is not None:
        noise_x = spec.white_equivalent(chain_impulse(s, fs, "acceleration"), fs)
        nv = spec.std_through(chain_impulse(s, fs, "velocity"), fs)
        # the direction threshold from the spectrum, unless it leaves under 90 % of
        # the rows the first estimate's does (THRESHOLD_KEEP): a quantised sensor's steps add
        # noise only where the arm crosses them, and the spectrum, read there, called
        # a slowly moving arm's whole motion uncertain (refused, where the first
        # estimate's rows named the quantum)
        if rows_clear_of(keep, np.abs(vf) <= DIRECTION_Z * nv, reach).mean() >= THRESHOLD_KEEP * valid.mean():
            noise_v = nv
        v_thr = DIRECTION_Z * noise_v
    valid = rows_clear_of(keep, np.abs(vf) <= v_thr, reach)
    ripple = driven_ripple(sig, float(coef[0]))
    out = Signals(t, u, x, xf, vf, af, dt, s, keep, valid, noise_x, noise_v, v_thr, spec, ripple)
    signed = rows_clear_of(keep, out.uncertain, reach)
    out.signed_share = float(signed.mean())
    out.noise_share = float(valid.mean())
    if signed.mean() >= RIPPLE_MIN_USABLE or valid.mean() < RIPPLE_MIN_USABLE:
        out.valid = signed
    else:  # no rows could be signed: the noise rule's rows, with the misfit the ripple makes
        out.v_ripple = None
    return out


def balance_coefficients(sig: Signals) -> np.ndarray | None:
    """``(J, B, K, h0, Fc)`` of eq. (3) fitted on ``sig``'s usable rows at the full rate
    (the rows' samples, the Butterworth-filtered signals, the friction's sign zero where
    the direction is uncertain: eq. (3) holds sample by sample on the filtered signals,
    so the decimation filter is not needed for a first fit); None where fewer than 50
    rows are usable or the inertia is not positive."""
    sign = np.where(np.abs(sig.vf) <= sig.v_threshold, 0.0, held_sign(sig.vf))
    at = sig.keep[sig.valid]
    if at.size < 50:
        return None
    A = np.column_stack([sig.af[at], sig.vf[at], sig.xf[at], np.ones(at.size), sign[at]])
    scale = np.abs(A).max(axis=0).clip(1e-300)
    coef = np.linalg.lstsq(A / scale, sig.force()[at], rcond=None)[0] / scale
    return coef if coef[0] > 0 and np.isfinite(coef).all() else None


def driven_ripple(sig: Signals, J: float) -> np.ndarray:
    """(n,) m/s: the magnitude, at each sample, of the velocity the recorded input
    drives in the inertia ``J`` above the position's Butterworth cutoff, times
    :data:`RIPPLE_MARGIN`: ``HP(integral of the aligned input)/J``, ``HP`` one minus
    the zero-phase Butterworth.  (Its envelope over a Butterworth period was tried: it
    made the open-loop PRBS nulls with low-pass noise `consistent` but cost friction
    names and a closed-loop Stribeck verdict,
    docs/studies/2026-11-28-prbs-coloured-nulls.md.)  The filtered velocity lacks exactly this
    part of a mass's velocity, so where ``|vf|`` is within it the true velocity may
    have the other sign: an open-loop PRBS's ripple (20 x the noise threshold on the
    proving ground) and the zero-phase filter's pre-ringing before a closed loop's step
    otherwise left 60-100 % of the rows with a friction sign the arm did not have."""
    ua = align(sig.u)
    hp = ua - sig.force()  # the Butterworth of the aligned input
    w = np.cumsum(hp) * (sig.dt / J)
    w = w - sig.butter(w)
    return RIPPLE_MARGIN * np.abs(w)


def sensor_noise(sig: Signals, coef: np.ndarray):
    """The position noise's spectrum (:class:`servo.diagnose.noise.NoiseSpectrum`) of
    :mod:`servo.diagnose.noise`: the residual of eq. (3) (``coef``,
    :func:`balance_coefficients`) at the full rate on the recorded position, read above
    the rows' band with the direction-uncertain samples gated out; None where the read
    band is too thin (the caller keeps what the Butterworth removes)."""
    from servo.diagnose import noise

    fs = 1.0 / sig.dt
    sign = np.where(np.abs(sig.vf) <= sig.v_threshold, 0.0, held_sign(sig.vf))
    ua = align(sig.u)
    J, B, K, h0, Fc = (float(c) for c in coef)
    e = J * second_difference(sig.x, sig.dt) + B * derivative(sig.x, sig.dt) + K * sig.x + h0 + Fc * sign - ua
    st = sig.settings
    cut = slice(st.trim_start, sig.n - st.trim_end)
    q = max(int(st.decimate), 1)
    # gated out: where the direction is uncertain, and beside every sign change (a true
    # reversal's switch is placed within a sample at best; the zero-phase filter's
    # pre-ringing before a closed loop's step flips the filtered velocity for a few samples)
    flips = np.zeros(sig.n, bool)
    flips[1:] = np.diff(np.sign(sig.vf)) != 0
    return noise.estimate(e[cut], J, fs, 0.4 * fs / q if q > 1 else 0.45 * fs, ((sign == 0) | flips)[cut],
                          int(math.ceil(noise.GUARD * fs / st.cutoff(fs))))


def chain_impulse(settings: RobustSettings, fs: float, kind: str) -> np.ndarray:
    """Full-rate impulse response (N,) of a chain the diagnosis applies to the position:
    ``"acceleration"`` (Butterworth zero-phase, second difference, the rows' decimation
    filter: its energy is a row's variance per unit white noise, whichever phase the
    decimation keeps; 1/s^2) or ``"velocity"`` (Butterworth, the rows' derivative; 1/s)."""
    q = max(int(settings.decimate), 1)
    b, a = butter_ba(settings.butter_order, settings.cutoff(fs) / (fs / 2))
    N = 400 * max(q, 2) + 1
    z = np.zeros(N)
    z[N // 2] = 1.0
    xf = signal.filtfilt(b, a, z, padlen=3 * settings.butter_order)
    if kind == "velocity":
        return derivative(xf, 1.0 / fs)
    h = second_difference(xf, 1.0 / fs)
    if q > 1:
        h = signal.sosfiltfilt(cheby_sos(settings.decimate_order, settings.decimate_ripple_db, q), h)
    return h


def rows_clear_of(keep: np.ndarray, bad: np.ndarray, reach: int) -> np.ndarray:
    """(m,) bool: the rows (full-rate indices ``keep``, (m,)) with no ``bad`` sample
    ((n,) bool) within ``reach`` samples either side, the decimation filter's extent."""
    if not bad.any():
        return np.ones(keep.size, bool)
    n = bad.size
    c = np.concatenate([[0], np.cumsum(bad)])
    return (c[np.clip(keep + reach + 1, 0, n)] - c[np.clip(keep - reach, 0, n)]) == 0


def distance_since_reversal(x: np.ndarray, v: np.ndarray, threshold: float) -> np.ndarray:
    """Distance (m) travelled since the latest velocity reversal, per sample.

    The direction changes when ``v`` crosses ``-+threshold`` (a Schmitt trigger, as the
    compensator's); the reversal point is the extreme position reached before the
    change.  Before the first reversal the distance is measured from the first sample."""
    s = np.where(v > threshold, 1.0, np.where(v < -threshold, -1.0, 0.0))
    idx = np.flatnonzero(s)
    if idx.size == 0:
        return np.zeros_like(x)
    # hold the last non-zero direction
    held = np.zeros_like(s)
    held[idx] = s[idx]
    pos = np.maximum.accumulate(np.where(held != 0, np.arange(s.size), 0))
    held = s[pos]
    held[: idx[0]] = s[idx[0]]
    change = np.flatnonzero(np.diff(held) != 0) + 1  # first sample of each new direction
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [s.size]])
    out = np.empty_like(x)
    prev_ext = x[0]
    for a, b in zip(starts, ends):
        seg = x[a:b]
        out[a:b] = np.abs(seg - prev_ext)
        prev_ext = seg.max() if held[a] > 0 else seg.min()
    return out


__all__ = ["Signals", "align", "distance_since_reversal", "held_sign", "make_signals", "velocity_noise_gain"]

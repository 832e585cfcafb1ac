"""The rows' band: the decimation of the force-balance rows, chosen from the recording.

The rows (:mod:`servo.diagnose.signals`) are decimated by ``q`` after a zero-phase
Butterworth on the position at ``fs/q`` (``fs/10`` at the default ``q = 10``); they
cover ``0 .. 0.4*fs/q`` Hz, the passband of the decimation filter.  Every row whose
filter reaches a sample where the direction of motion is uncertain (about
``15*q`` samples either side) is kept out of the fits.  A fixed ``q = 10`` therefore
fails a recording that reverses often relative to its sample rate: at 750 Hz with a
reversal every second, nearly every row's filter reaches a reversal, and the
diagnosis refused with "too few usable rows ... record more motion", which was not
the cause.

**Where the input has power** bounds ``q`` first with the rule ``"power"`` (an option,
:data:`RULES`; the default rule ``"reversals"`` states the power edge in its note and
leaves ``q`` to the reversals): the band over which the measured motion stands 20 dB over the position
sensor's noise (:mod:`servo.diagnose.power_band`) must lie inside the rows' band, so
only the candidates ``q <= 0.4*fs/edge`` are tried (all of them where the power ends
inside the band of 10; the smallest alone where no candidate covers it).  The reversal
rule below then chooses among those: never a ``q`` the reversals forbid, and a ``q``
larger than 10 is never tried (the rows' averaging and the study's levels stay those
of the default).

Among them, :func:`choose` tries ``q`` largest first (the most averaging and
the fewest rows) and keeps the first whose rows are at least :data:`USABLE_MIN` usable
with the friction sign the arm had (``Signals.usable_share``: where the ripple rule fell
back to the noise rule's rows, those rows carry a wrong sign's misfit and do not count);
failing that, the one with the most usable rows, at least :data:`FALLBACK_MIN` or rows
thinned by a dither alone (:func:`dithered`: a closed loop holding the arm between
steps); failing every one, it
refuses with the cause it measured (an arm that barely moves, or reversals too close
together for any decimation, with their count and spacing).  The note says why: the
power edge against the bands, the reversals' median spacing and the usable share.  An
explicit ``Options.settings`` (``--decimate Q``) is used as given.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from servo.diagnose import power_band
from servo.diagnose.scope import OutOfDomain
from servo.identify.regressors import IdentificationError, RobustSettings
from servo.io.recording import Recording

#: decimation factors tried, the default first
CANDIDATES = (10, 8, 6, 5, 4, 3)
#: the rules a decimation is chosen by (``Options.band``, ``--decimate``), the default first:
#: the power rule is an option (docs/studies/2026-11-24-band-from-input-power.md: on the concealed-effect study it
#: raised three detection thresholds a size step and the locate tests' flags on nulls)
RULES = ("reversals", "power")
#: a decimation is kept when at least this share of its rows is usable
USABLE_MIN = 0.6
#: failing that, the decimation with the largest share of usable rows, if at least this
#: share of its rows is usable (below it the rows are a few islands between reversals
#: or sticks, and a diagnosis on them is refused with the cause)
FALLBACK_MIN = 0.3
#: ... and only if that share is this many times the default's: where the
#: rows are few because the arm dwells (not because reversals fall within the filter's
#: reach) a smaller decimation gains little and widens the band for nothing
GAIN_MIN = 1.5


def settings_for(q: int, fs: float, cutoff_hz: float | None = None) -> RobustSettings:
    """The path decimating by ``q``: the Butterworth at ``fs/q`` (2.5 x the rows' band
    edge, as the default ``fs/10`` at ``q = 10``) unless ``cutoff_hz`` is given."""
    return replace(RobustSettings(), decimate=int(q), cutoff_hz=float(cutoff_hz) if cutoff_hz else fs / q)


def band_hz(settings: RobustSettings, fs: float) -> float:
    """Upper edge of the rows' band (Hz): the decimation filter's passband, ``0.4*fs/q``
    (the full band, ``fs/2``, without decimation)."""
    q = max(int(settings.decimate), 1)
    return 0.4 * fs / q if q > 1 else 0.5 * fs


def reversals(sig) -> tuple[int, float]:
    """Direction changes of the filtered velocity (a Schmitt trigger at the direction
    threshold) and the median number of samples between them."""
    v = sig.vf
    s = np.where(v > sig.v_threshold, 1, np.where(v < -sig.v_threshold, -1, 0))
    idx = np.flatnonzero(s)
    if idx.size < 2:
        return 0, float(sig.n)
    ch = idx[1:][np.diff(s[idx]) != 0]
    gaps = np.diff(ch)
    return int(ch.size), float(np.median(gaps)) if gaps.size else float(sig.n)


def choose(rec: Recording, opt, prepare):
    """The design of the chosen band (module doc): ``(design, note)`` with ``note`` why
    this decimation.  ``prepare(rec, settings, opt)`` makes a design or raises
    :class:`IdentificationError` (too short, too few usable rows).  ``opt.band`` is the
    rule (:data:`RULES`): ``"reversals"`` (the default) uses the reversals alone and
    states the power edge in the note, ``"power"`` bounds the decimation by the power
    edge first."""
    fs = 1.0 / rec.dt
    if opt.settings is not None:
        try:
            return prepare(rec, opt.settings, opt), f"decimation by {opt.settings.decimate} as given"
        except IdentificationError as exc:
            raise _refusal(rec, [(opt.settings.decimate, None, exc)], exc, opt.settings) from None
    rule = getattr(opt, "band", RULES[0])
    if rule not in RULES:
        raise IdentificationError(f"unknown band rule {rule!r} (choose {' or '.join(RULES)}, or a decimation factor)")
    made: dict = {}

    def attempt(q: int):
        if q not in made:
            try:
                made[q] = (prepare(rec, settings_for(q, fs, getattr(opt, "cutoff_hz", None)), opt), None)
            except IdentificationError as exc:
                made[q] = (None, exc)
        return made[q]

    cands, power = CANDIDATES, ""
    first = attempt(CANDIDATES[0])[0]
    if rule == "power" or first is not None:  # the power edge: the rule's bound, or the reversal rule's note
        edge, qp = power_decimation(rec, first, fs, getattr(opt, "cutoff_hz", None))
        top = band_hz(settings_for(CANDIDATES[0], fs), fs)
        power = (f"the position stands {power_band.MARGIN_DB:.0f} dB over its noise floor up to {edge:.4g} Hz, "
                 + (f"inside the band of {CANDIDATES[0]} ({top:.4g} Hz)" if qp == CANDIDATES[0] else
                    f"beyond the band of {CANDIDATES[0]} ({top:.4g} Hz), within that of {qp} "
                    f"({band_hz(settings_for(qp, fs), fs):.4g} Hz)"))  # fmt: skip
        if rule == "power":
            cands = tuple(q for q in CANDIDATES if q <= qp)
    d, why = _by_reversals(cands, attempt, rec)
    q = d.sig.settings.decimate
    if rule == "power" or not power:
        return d, f"decimation by {q}: " + "; ".join(w for w in (power, why) if w)
    if qp < q:
        power += ", which --decimate power would take"
    return d, f"decimation by {q}: {why}; {power}"


def power_decimation(rec: Recording, design, fs: float, cutoff_hz: float | None = None) -> tuple[float, int]:
    """``(edge, q)``: where the input has power (:func:`servo.diagnose.power_band.edge_hz`,
    with the position noise of ``design``'s rows, or of the default path's signals if
    ``design`` is None) and the largest candidate decimation whose band covers it."""
    if design is not None:
        noise = design.sig.noise_x
    else:
        from servo.diagnose.signals import make_signals

        try:
            noise = make_signals(rec, settings_for(CANDIDATES[0], fs, cutoff_hz)).noise_x
        except IdentificationError:
            return 0.0, CANDIDATES[0]  # the reversal rule's refusal says why
    edge = power_band.edge_hz(rec.x, fs, noise)
    return edge, power_band.decimation_for(edge, fs, CANDIDATES)


def _by_reversals(cands: tuple, attempt, rec: Recording):
    """The reversal rule over ``cands`` (largest first, the first one its default):
    ``(design, why)``, or raises the refusal with its measured cause."""
    tried = []
    for q in cands:
        d, exc = attempt(q)
        tried.append((q, d, exc))
        if d is None:
            continue
        if d.sig.usable_share >= USABLE_MIN:
            n_rev, gap = reversals(d.sig)
            rev = f"the motion reverses every {gap:.0f} samples (median)" if n_rev > 1 else "the motion hardly reverses"
            if q == cands[0]:
                return d, f"{rev}, {100 * d.sig.usable_share:.0f} % of the rows usable"
            return d, (f"{rev}: by {cands[0]} only {100 * _usable(tried, cands[0]):.0f} % of the rows were usable "
                       "(reversals within the decimation filter's reach)")  # fmt: skip
    default = next((d for q, d, _ in tried if q == cands[0] and d is not None), None)
    ok = [(q, d) for q, d, _ in tried if d is not None and q != cands[0] and _enough(d.sig)]
    if ok:
        q, d = max(ok, key=lambda t: float(t[1].sig.usable_share))  # shares: the row counts differ with q
        if default is None or d.sig.usable_share >= GAIN_MIN * default.sig.usable_share:
            return d, (f"the most usable rows of the decimations tried ({100 * d.sig.usable_share:.0f} "
                       f"%, {100 * _usable(tried, cands[0]):.0f} % by {cands[0]}; reversals within the "
                       "decimation filter's reach)")  # fmt: skip
    if default is not None:  # no decimation does much better: the rows are few for another reason (the arm dwells)
        return default, (f"{100 * default.sig.usable_share:.0f} % of the rows usable; no other decimation tried "
                         "gives many more usable rows")  # fmt: skip
    last_exc = next((e for _, _, e in reversed(tried) if e is not None), None)
    raise _refusal(rec, tried, last_exc or IdentificationError("too few usable rows"))


def _enough(sig) -> bool:
    """Whether a decimation's rows are enough for the fallback (module doc): at least
    :data:`FALLBACK_MIN` usable, or thinned by a dither alone (:func:`dithered`)."""
    return bool(sig.usable_share >= FALLBACK_MIN or dithered(sig))


def dithered(sig) -> bool:
    """Whether ``sig``'s rows are few only because the ripple rule thins them: the noise
    rule alone leaves :data:`FALLBACK_MIN` of them (a closed loop's dither at rest, not
    reversals within the filter's reach) and the ripple rule at least the share it is
    applied down to (:data:`servo.diagnose.signals.RIPPLE_MIN_USABLE`).  Such rows are
    diagnosed (``servo.diagnose.job.prepare`` refuses other rows under 20 %)."""
    from servo.diagnose.signals import RIPPLE_MIN_USABLE

    return bool(sig.v_ripple is not None and (sig.noise_share or 0.0) >= FALLBACK_MIN
                and sig.usable_share >= RIPPLE_MIN_USABLE)  # fmt: skip


def _usable(tried, q) -> float:
    for qq, d, _ in tried:
        if qq == q and d is not None:
            return float(d.sig.usable_share)
    return 0.0


def _refusal(rec: Recording, tried: list, last_exc, settings: RobustSettings | None = None) -> IdentificationError:
    """Why no decimation works, from what was measured on the least decimated path."""
    from servo.diagnose.signals import make_signals

    q = tried[-1][0]
    fs = 1.0 / rec.dt
    msg = str(last_exc) if last_exc is not None else ""
    if "too few usable rows" not in msg:
        return last_exc if isinstance(last_exc, IdentificationError) else IdentificationError(msg)
    try:
        sig = make_signals(rec, settings or settings_for(q, fs))
    except IdentificationError as exc:
        return exc
    slow = float(np.mean(np.abs(sig.vf) <= sig.v_threshold))
    n_rev, gap = reversals(sig)
    if slow >= 0.5:
        return OutOfDomain(
            f"too few usable rows: the speed is within its noise ({sig.v_threshold:.3g} m/s) in {100 * slow:.0f} % of "
            "the samples, where the direction of motion is unknown; the arm barely moves: record more motion")
    from servo.diagnose.signals import filter_reach

    reach = filter_reach(sig.settings)
    return OutOfDomain(
        f"too few usable rows: the motion reverses {n_rev} times, every {gap:.0f} samples (median), and the rows "
        f"within the decimation filter's reach of a reversal (+-{reach} samples at decimation by {q}, the least tried) "
        f"are unusable ({100 * sig.valid.mean():.0f} % of rows left); record at a higher sample rate (or with fewer "
        "reversals) so that reversals are further apart in samples" + ("" if settings is None else
                                                                         ", or try a smaller --decimate"))  # fmt: skip


__all__ = ["CANDIDATES", "RULES", "USABLE_MIN", "band_hz", "choose", "dithered", "power_decimation", "reversals", "settings_for"]

"""Track-following design on the double integrator ``J*s^2``: lead-lag (PID) with an
integrator, notches at the flexible modes, a low-pass; discretised to two cascades.

The design is continuous (:mod:`servo.design.analog`); its one free choice, the lead ratio,
and its gain are then set on the *exact discrete loop* (:func:`servo.design.loop.open_loop`
with the double integrator, the hold between the rates, the zero-order hold and an
optional input delay), so that the loop the controller will run crosses over at
``crossover_hz`` with ``phase_margin_deg``: the integrator's lag, the notches' and the
low-pass's lag at the crossover, the sample-and-hold and the delay are all paid for by the
lead.
"""
from __future__ import annotations

import math

import numpy as np
import control
from scipy.optimize import brentq

from servo.design import analog, discretise, loop
from servo.design.design import Design

#: Largest lead ratio the design will use (about 78 degrees of lead).
MAX_LEAD_RATIO = 100.0


def _build(J, fs, pes_every, method, slow_block, fast_blocks, info, peak_blocks=()):
    # a zero-order hold does not keep a notch's zeros (a 20 dB notch comes out ~12 dB):
    # in a "zoh" design the peaks, the notches and the low-pass are matched
    slow = np.vstack([discretise.sos(b, fs / pes_every, "matched" if method == "zoh" and b is not slow_block else method)
                      for b in (slow_block, *peak_blocks)])  # fmt: skip
    fast = [discretise.sos(b, fs, "matched" if method == "zoh" else method) for b in fast_blocks]
    fast = np.vstack(fast) if fast else np.zeros((0, 6))
    return Design(slow, fast, fs, pes_every, integrators=1 if slow_block.params.get("integrator_ratio") else 0,
                  blocks=(slow_block, *peak_blocks, *fast_blocks), method=method, info=info)  # fmt: skip


def track_following(
    J: float,
    fs: float,
    crossover_hz: float,
    phase_margin_deg: float | None = 40.0,
    *,
    lead_ratio: float | None = None,
    integrator_ratio: float | None = 5.0,
    notches=(),
    peaks=(),
    lowpass_hz: float | None = None,
    lowpass_zeta: float = 0.7,
    pes_every: int = 1,
    method: str = "bilinear",
    delay_s: float = 0.0,
) -> Design:
    """A track-following :class:`Design` for the plant ``J*x'' = u``.

    ``J``: inertia (A*s^2/m); ``fs``: tick rate (Hz); ``crossover_hz``: open-loop gain
    crossover (Hz); ``phase_margin_deg``: phase margin (deg) the lead ratio is solved for
    on the discrete loop, or ``lead_ratio`` (``wp/wz >= 1``) given instead (then
    ``phase_margin_deg`` is ignored); ``integrator_ratio``: ``crossover / integrator
    corner`` (None: no integrator); ``notches``: ``(f_hz, depth_db, width)`` triples
    (:func:`servo.design.analog.notch`: depth in dB at the centre, relative width);
    ``peaks``: ``(f_hz, gain_db, width, phase_deg)`` peak filters at the PES rate
    (:func:`servo.design.analog.peak`: the loop gain raised at a runout harmonic or a
    disturbance band; the lead is solved with them in place);
    ``lowpass_hz``/``lowpass_zeta``: a second-order low-pass (None: none); ``pes_every``:
    ticks per PES sample (the slow cascade runs at ``fs/pes_every``, notches and low-pass
    at ``fs``); ``method``: "bilinear" (prewarped at the crossover for the lead-lag, at each
    notch's centre and the low-pass corner), "matched" or "zoh"
    (:mod:`servo.design.discretise`; with "zoh" the notches and low-pass are matched, a
    hold equivalent losing a notch's depth); ``delay_s``: plant input delay (s) the phase margin
    accounts for.

    The gain puts the discrete loop's gain crossover exactly at ``crossover_hz``.  Raises
    ValueError when no lead ratio up to :data:`MAX_LEAD_RATIO` gives the requested phase
    margin (a wide lead also lifts the gain above the crossover, and past a point loses
    margin to the sample-and-hold and the delay), a notch or the low-pass sits at or above Nyquist of the tick rate, the crossover
    above the PES Nyquist, or a cascade is too long or unstable.
    """
    if not (J > 0 and fs > 0 and 0 < crossover_hz < fs / pes_every / 2):
        raise ValueError(f"need J > 0, fs > 0 and 0 < crossover_hz < PES Nyquist ({fs / pes_every / 2:g} Hz)")
    if integrator_ratio is not None and not integrator_ratio > 1:
        raise ValueError(f"integrator_ratio = {integrator_ratio}: must be > 1 (the integrator's corner below the crossover)")
    fast_blocks = [analog.notch(*n) for n in notches]
    peak_blocks = [analog.peak(*pk) for pk in peaks]
    for b in peak_blocks:
        if b.match_hz >= fs / pes_every / 2:
            raise ValueError(f"{b.name} is at or above the PES Nyquist frequency ({fs / pes_every / 2:g} Hz)")
    if lowpass_hz is not None:
        fast_blocks.append(analog.lowpass(lowpass_hz, lowpass_zeta))
    plant = loop.double_integrator(J)
    wc = 2 * math.pi * crossover_hz

    def unit_loop(a):
        slow = analog.lead_integrator(crossover_hz, a, integrator_ratio, 1.0)
        d = _build(J, fs, pes_every, method, slow, fast_blocks, {}, peak_blocks)
        L = loop.open_loop(d, plant, delay_s)
        return complex(L(np.exp(1j * wc / d.fs_pes))), slow

    def phase_margin(a):
        return math.degrees(np.angle(unit_loop(a)[0])) % 360.0 - 180.0

    if lead_ratio is None:
        if phase_margin_deg is None:
            raise ValueError("give phase_margin_deg or lead_ratio")
        grid = np.geomspace(1.0, MAX_LEAD_RATIO, 33)
        pms = np.array([phase_margin(a) for a in grid])
        best = int(np.argmax(pms))
        if pms[best] < phase_margin_deg:
            raise ValueError(f"a {phase_margin_deg:g} deg phase margin at {crossover_hz:g} Hz is out of reach: the "
                             f"most a lead of up to {MAX_LEAD_RATIO:g}:1 gives is {pms[best]:.1f} deg "
                             f"(lead ratio {grid[best]:.3g})")  # fmt: skip
        if pms[0] >= phase_margin_deg:
            lead_ratio = 1.0
        else:  # the smallest lead that gives the margin: PM rises from grid[0] to grid[best]
            i = int(np.nonzero(pms[: best + 1] >= phase_margin_deg)[0][0])
            lead_ratio = brentq(lambda a: phase_margin(a) - phase_margin_deg, grid[i - 1], grid[i], xtol=1e-12)
    h, _ = unit_loop(lead_ratio)
    gain = 1.0 / abs(h)
    slow = analog.lead_integrator(crossover_hz, lead_ratio, integrator_ratio, gain)
    # the margin above is a phase taken mod 360 deg, blind to lag beyond -360 deg (a long
    # delay): the loop it designs must also be stable, checked on its closed-loop poles
    cl = control.feedback(loop.open_loop(_build(J, fs, pes_every, method, slow, fast_blocks, {}, peak_blocks), plant, delay_s), 1)
    radius = float(np.max(np.abs(cl.poles()))) if cl.nstates else 0.0
    if radius >= 1.0:
        raise ValueError(f"the loop designed for {crossover_hz:g} Hz, {phase_margin_deg} deg is unstable on the double "
                         f"integrator (closed-loop pole radius {radius:.4f}): lower the crossover or the delay")  # fmt: skip
    info = dict(kind="track_following", J=J, crossover_hz=crossover_hz, phase_margin_deg=phase_margin(lead_ratio),
                lead_ratio=lead_ratio, integrator_ratio=integrator_ratio, delay_s=delay_s,
                notches=[list(n) for n in notches], peaks=[list(pk) for pk in peaks], lowpass_hz=lowpass_hz,
                lowpass_zeta=lowpass_zeta)  # fmt: skip
    return _build(J, fs, pes_every, method, slow, fast_blocks, info, peak_blocks)

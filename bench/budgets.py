"""Per-sample time budgets, as fractions of the sample period of the config.

Every budget is ``fraction * period`` with the period taken from ``run.sample_rate_hz``
(20 us at the default 50 kHz), so a faster servo gets tighter budgets with no number to
edit.  The fractions and why (figures measured on the team's shared 2-core VM, quiet;
when the host's cores are contended everything slows by up to ~2.4x, so each budget
keeps at least ~2x over the worst loaded figure seen, and ratios are measured against
references in the same run, where the slowdown cancels):

* **controller tick**, compiled (Dahl update + compensator + PI + limits), 1/100: the
  arithmetic of one sample must be a small part of the tick, whose cost is the Python
  dispatch around it (~0.5 us per kernel call).  ~30-50 ns measured.
* its **parts**: the Dahl update 1/100, the whole tick's budget (it is the costliest
  part: with alpha != 1 it calls ``pow`` twice, ~40 ns), the compensator and the PI loop
  1/1000 each (a few multiply-adds, ~1.5 ns).
* the **controller tick with every compensator term on** (issue 14: viscous and Coulomb
  asymmetry, Stribeck, a 4-harmonic periodic force, the kf(x) divisor, both authority
  clips), 1/200: 100 ns at 50 kHz, the issue's goal.  68-80 ns measured with the host
  calm, 252 ns at load 7 on the 2 cores: no wall-clock margin holds that, so it is
  asserted in a form the load cancels from, against the paper's tick timed in adjacent
  pairs (:data:`EVERY_TERM_OVER_PAPER_MAX`).
* **plant**: ``plant_step`` 1/8 (four RK4 sub-steps with the Dahl closed form and six
  modes, ~0.5 us: the simulated drive is most of the fast path), ``plant_measure`` and
  the link's ``shift_in`` 1/200 (~15 ns).
* **tick path**, per tick through the scheduler and the driver interface with
  ``SimDriver`` (read, controller, write, excitation/estimator/log tasks): 1/4 (the
  issue's target; it was 3/4 while processes landed in a slow mode of 8-9 us).  A paced
  tick starts at its deadline and must end before the next one; the three quarters left
  absorb wake-up jitter and let the loop catch up after a late tick (a lateness L is
  recovered in ``L / (3T/4)`` ticks).  3.3-3.5 us median measured on 2026-11-28 in
  every one of 14 processes at load 20-23 (16-18 %), 48.5k instructions a tick.
* **fast path**, per simulated sample of the all-compiled loop with logging: 1/4, i.e.
  at least 4x faster than real time (it is the path for long simulations and sweeps;
  ~0.6 us measured, 33x real time).
* **first tick** after ``configure``: 10 periods.  Nothing may compile, draw noise or
  collect garbage in it (each costs 0.2 ms to seconds); what is left is cold caches.
"""
from __future__ import annotations

from dataclasses import dataclass

from servo.config import Config


@dataclass(frozen=True)
class Budget:
    """``fraction`` of the sample period, and why."""

    fraction: float
    why: str

    def ns(self, cfg: Config) -> float:
        """The budget in ns at the config's sample rate."""
        return self.fraction * cfg.dt * 1e9


BUDGETS = {
    "controller_tick": Budget(1 / 100, "one sample of the compiled controller"),
    "controller_tick_every_term": Budget(1 / 200, "one sample of the compiled controller, every compensator term on"),
    "dahl_update": Budget(1 / 100, "Dahl estimate, eq. (6-7), alpha == 1 or not"),
    "compensate": Budget(1 / 1000, "compensation current, eq. (9)"),
    "holding_pi": Budget(1 / 1000, "PI holding loop with anti-windup"),
    "plant_step": Budget(1 / 8, "one sample of the simulated drive"),
    "plant_measure": Budget(1 / 200, "the drive's sensor"),
    "shift_in": Budget(1 / 200, "the link's 3-tick command queue"),
    "tick_path": Budget(1 / 4, "one tick through scheduler + driver interface + SimDriver"),
    "fast_path": Budget(1 / 4, "one simulated sample of the all-compiled loop (>= 4x real time)"),
    "first_tick": Budget(10.0, "the first tick after configure"),
}

#: Numba/C time ratio, same arithmetic, same run: at most this ("near 1").
NUMBA_OVER_C_MAX = 2.5
#: Numba/C time ratio of the PI tick with every compensator term on (issue 14's goal: 1.1).
#: Measured 1.13-1.16 (paired medians at load 1 to 8 on the 2 cores; the paper's tick
#: measured 1.10-1.23 in the same runs): the bound is the worst seen x 1.5.
NUMBA_OVER_C_EVERY_TERM_MAX = 1.75
#: Numba/C of the track-following tick (biquads at two rates, calls Numba does not
#: inline): measured 1.6-1.83 at load 1-3, and once above 2.5 in a run at load 5 on the
#: 2 cores; the bound is twice the usual, still far below what a kernel falling out of
#: compiled code costs (10x and more).
NUMBA_OVER_C_TRACK_MAX = 3.5
#: The tick with every compensator term on over the paper's tick (eq. 6-9 only), timed in
#: adjacent pairs: the 1/200 budget in a form the host's load cancels from.  The paper's
#: tick measures ~21-24 ns with the host calm, so 4.0 is ~100 ns; measured 2.2-3.0.
EVERY_TERM_OVER_PAPER_MAX = 4.0
#: The tick path (scheduler + driver interface + SimDriver) with every compensator term on
#: over the paper's, rounds alternated: the terms are ~50 ns of a ~4 us tick (~1 %);
#: measured 0.98-1.06 at load 7-8 on 2 cores, but 0.62 and 1.36 in two CI runs of the
#: same code on an idle machine (each run's two loops differ by up to 40 % in their
#: medians, whichever has the terms: a per-process effect the alternation does not
#: cancel).  A guard against a gross regression (a term falling out of compiled code
#: costs 10x), not a measure of the terms' cost: that is the controller tick's ratios.
TICK_PATH_EVERY_TERM_OVER_PAPER_MAX = 2.0
#: The track and NSS controllers' tick over the PI kind's, timed in adjacent pairs: at
#: most this.  1.40 (track, 36-37 ns over 26-27) and 1.31 (NSS) at load 12 on the 2
#: cores, where their figures alone had failed the 200 ns budget (229 ns at load 13).
KIND_OVER_PI_TICK_MAX = 2.0
#: Python/Numba time ratio of the controller tick: at least this (compiling must pay).
PYTHON_OVER_NUMBA_MIN = 20.0
#: Cold start (process start to first tick of ``servo run``) at most this multiple of the
#: time the interpreter takes to import numba, numpy, scipy.linalg and matplotlib.
STARTUP_OVER_DEPENDENCIES_MAX = 3.0
#: Cold start of ``servo run`` at most this multiple of ``import numpy, numba`` timed just
#: before it.  Medians of 3: 2.64 at load 28 (2026-11-28, the drive built on one BLAS
#: thread and the provenance made after the runs; single processes 2.37-3.75 at load
#: 6-9); before that 2.6 at load 13, 2.9 at load 17, 3.1 at load 7; the code that
#: imported scipy.signal and matplotlib before the first tick: 5.4 at load 13, 4.8 at
#: load 7.  Later that day, with the helpers of the composed kernels loaded only when
#: needed (14 kernels before the first tick instead of 58): 2.10 at load 25, 2.20 at
#: load 16, 1.79 beside two spinners at load 17-20 (the code before in the same runs:
#: 2.42, 2.60, 2.36); at load 9-10 with the floor at 0.47-0.53 s (near its idle
#: 0.3-0.5 s): 1.04-1.27 s, 2.11-2.57 per process, median 2.19 (the code before: 2.45).
#: The issue's goal, under 1 s idle, is about 2.5x that floor: within reach, not shown
#: idle.  Single processes vary (one at 3.17 at load 4, its median of 3 2.19); the bound
#: is on the median of 3: the worst median seen since (2.26, beside two spinners) x ~1.3.
STARTUP_OVER_IMPORT_FLOOR_MAX = 3.0
#: ``servo diagnose``'s fixed cost, process start to its recording read
#: (``bench/startprobe.py``), at most this multiple of ``import numpy, numba`` timed just
#: before it: numba, the scipy modules the diagnosis uses and its cached kernels.
#: Measured 4.00 (median of 3) at load 28 on 2026-11-28; later that day 3.24-4.12 at load
#: 8-27 with and without two spinners, and 3.51 (1.33 s on a 0.38 s floor) at load 7-8:
#: the issue's goal, under 1.5 s idle, met at that load.  The bound: the worst seen x ~1.2.
DIAGNOSE_FIXED_OVER_IMPORT_FLOOR_MAX = 5.0
#: The fast path with its run log (``servo run --fast``: windows and noise drawn a block
#: ahead by a thread, watchdog, journal writer thread) over the same closed loop in C
#: writing the same rows to memory, CPU time of the loop's thread, paired rounds.  The
#: issue's goal is 1.2; measured 1.153-1.167 at load 12-15 and 1.156, 1.156, 1.163
#: beside two spinning processes (load 21-27) on 2026-11-28, after the plant's RK4
#: sub-step and its acceleration were inlined (the compiled kernel alone 1.08-1.09; before
#: that 1.20-1.21 at load 2-3 and 1.15-1.21 beside two spinners).  Later: 1.186 and
#: 1.289 in two clean CI runs (the kernel alone 1.10 and 1.09: the calls' overhead, not
#: the kernel, varies), 1.225 idle.  The bound: the worst seen x ~1.1.
FAST_PATH_OVER_C_MAX = 1.4

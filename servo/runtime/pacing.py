"""Wall-clock pacing for runs against a plant that lives in real time.

The scheduler counts ticks; a :class:`Pacer` ties tick ``k`` to the wall clock:

* absolute deadlines, ``deadline_k = t0 + k*period`` (``next += period``: no drift);
* wait = ``time.sleep`` until ``spin`` before the deadline, then spin on the clock;
* lateness ``now - deadline_k`` of every tick recorded in constant memory
  (:class:`~servo.runtime.durations.Durations`);
* overrun: the tick is entered after its deadline (the previous tick ran over its
  period).  Policy ``"count"`` counts and continues; ``"fault"`` raises
  :class:`OverrunFault` after ``max_consecutive`` overruns in a row, so the caller's
  lifecycle puts the drive in its safe state.

:func:`gc_paused` keeps the garbage collector out of a loop (``gc.disable``; restored
after).  :func:`realtime_section` collects, freezes and disables it, and asks the OS,
where it permits, for CPU affinity, ``SCHED_FIFO`` and locked memory; it reports what it
got and what it did not, one line each.  Pacing never changes a number: it only decides
*when* tick ``k`` runs (``tests/test_pacing.py`` checks a paced log equals the unpaced one).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field


from servo.errors import DriverError
from servo.runtime.durations import Durations


class OverrunFault(DriverError):
    """Too many consecutive deadline overruns: the host cannot keep up."""


class Pacer:
    """Paces ticks ``0..n-1`` at ``period_s`` on :func:`time.perf_counter_ns`.

    ``wait(k)`` returns at (or as soon as possible after) tick ``k``'s deadline.  Call
    :meth:`start` right before the first tick.
    """

    def __init__(self, period_s: float, n_ticks: int, spin_s: float = 100e-6, policy: str = "count",
                 max_consecutive: int = 10):  # fmt: skip
        if policy not in ("count", "fault"):
            raise ValueError("policy must be 'count' or 'fault'")
        self.period_ns = int(round(period_s * 1e9))
        self.spin_ns = int(round(spin_s * 1e9))
        self.policy = policy
        self.max_consecutive = max_consecutive
        self.n_ticks = n_ticks
        self.lateness = Durations()
        self._j = 0  # lateness values in lateness.buf not yet folded
        self.overruns = 0
        self.consecutive = 0
        self.t0 = 0
        self.k_last = -1

    def start(self) -> None:
        """Set the deadlines: tick ``k`` at ``start + (k + 1)*period``.  Tick 0 is one
        period away, so that it is waited for like any other (were its deadline "now",
        the call overhead alone would count it as an overrun)."""
        self.t0 = time.perf_counter_ns() + self.period_ns

    def wait(self, k: int) -> None:
        deadline = self.t0 + k * self.period_ns
        now = time.perf_counter_ns()
        if now > deadline:
            self.overruns += 1
            self.consecutive += 1
            if self.policy == "fault" and self.consecutive >= self.max_consecutive:
                self._record(k, now - deadline)
                self.finish()
                raise OverrunFault(
                    f"realtime: {self.consecutive} consecutive deadline overruns at tick {k} "
                    f"({(now - deadline) / 1e3:.0f} us late): the host cannot keep {1e9 / self.period_ns:g} Hz; "
                    "drive set to zero current"
                )
        else:
            self.consecutive = 0
            remaining = deadline - now - self.spin_ns
            if remaining > 0:
                time.sleep(remaining / 1e9)
            while time.perf_counter_ns() < deadline:
                pass
            now = time.perf_counter_ns()
        self._record(k, now - deadline)

    def _record(self, k: int, late_ns: int) -> None:
        self.lateness.buf[self._j] = late_ns
        self._j += 1
        if self._j == self.lateness.buf.shape[0]:
            self.lateness.fold(self._j)
            self._j = 0
        self.k_last = k

    def finish(self) -> None:
        """Fold the lateness values not yet counted (call after the last tick)."""
        self.lateness.fold(self._j)
        self._j = 0

    def report(self) -> dict:
        """Lateness distribution (us) of the ticks paced so far, and overruns."""
        self.finish()
        late = self.lateness
        if late.count == 0:
            return {"ticks": 0, "overruns": 0}
        p50, p99, p999 = (late.quantile(q) / 1e3 for q in (0.5, 0.99, 0.999))
        return {"ticks": late.count, "lateness_us_p50": p50, "lateness_us_p99": p99,
                "lateness_us_p999": p999, "lateness_us_max": late.max / 1e3, "overruns": self.overruns}  # fmt: skip


@dataclass
class RealtimeGrant:
    """What :func:`realtime_section` obtained from the OS; ``notes`` are one line each."""

    gc_frozen: bool = False
    affinity: list[int] | None = None
    sched_fifo: bool = False
    memory_locked: bool = False
    notes: list[str] = field(default_factory=list)


_MCL_CURRENT, _MCL_FUTURE = 1, 2


def _mlockall() -> str | None:
    libc_name = ctypes.util.find_library("c")
    if not libc_name:
        return "memory locking: no C library found"
    libc = ctypes.CDLL(libc_name, use_errno=True)
    if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:
        return f"memory locking: not permitted ({os.strerror(ctypes.get_errno())})"
    return None


def _munlockall() -> None:
    libc_name = ctypes.util.find_library("c")
    if libc_name:
        ctypes.CDLL(libc_name).munlockall()


@contextmanager
def gc_paused(collect: bool = False):
    """Keep the garbage collector out of the block: ``gc.disable()``, restored after;
    nests.  Objects allocated in the block are still freed by reference counting; only
    cycles wait.  ``collect``: first collect and ``gc.freeze()`` what survives (tens of ms
    once numba, scipy and matplotlib are loaded: worth it before a long real-time run,
    not before every short simulation of a sweep)."""
    was_enabled = gc.isenabled()
    if collect:
        gc.collect()
        gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        if collect:
            gc.unfreeze()
        if was_enabled:
            gc.enable()


@contextmanager
def realtime_section(cpu: int | None = None, fifo_priority: int | None = None, lock_memory: bool = False):
    """Prepare the process for a paced loop and restore it afterwards.

    Always: collect, freeze and disable the garbage collector (:func:`gc_paused`).
    Optional, where the OS permits: pin to ``cpu``; ``SCHED_FIFO`` at ``fifo_priority``;
    ``mlockall``.  Yields a :class:`RealtimeGrant`; what was refused is in its ``notes``,
    one line each.
    """
    grant = RealtimeGrant()
    old_affinity = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    old_policy = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else None
    old_param = os.sched_getparam(0) if hasattr(os, "sched_getparam") else None
    with gc_paused(collect=True):
        grant.gc_frozen = True
        try:
            if cpu is not None:
                try:
                    os.sched_setaffinity(0, {cpu})
                    grant.affinity = [cpu]
                except (OSError, AttributeError, ValueError) as exc:
                    grant.notes.append(f"CPU affinity to core {cpu}: not available ({exc})")
            if fifo_priority is not None:
                try:
                    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(fifo_priority))
                    grant.sched_fifo = True
                except (OSError, AttributeError) as exc:
                    grant.notes.append(f"SCHED_FIFO priority {fifo_priority}: not permitted ({exc})")
            if lock_memory:
                note = _mlockall()
                if note:
                    grant.notes.append(note)
                else:
                    grant.memory_locked = True
            yield grant
        finally:
            if grant.memory_locked:
                _munlockall()
            if grant.sched_fifo and old_policy is not None:
                try:
                    os.sched_setscheduler(0, old_policy, old_param)
                except OSError:
                    pass
            if grant.affinity is not None and old_affinity is not None:
                os.sched_setaffinity(0, old_affinity)

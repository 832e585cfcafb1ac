"""The deterministic tick scheduler.

Time is the tick counter ``k``, never the wall clock.  One tick::

    x, v = driver.read()                 sample k
    before-tasks, in order, when due     e.g. excitation / reference
    u = controller.tick(...)             every tick
    driver.write(u)                      the command of tick k
    after-tasks, in order, when due      e.g. estimators, logging

A task runs at ticks ``k`` with ``(k - offset) % every == 0``.  The order is the order of
the lists, fixed at construction.  On the first tick of :meth:`Scheduler.run` the
controller takes over bumplessly (``controller.start``) from the current the drive
applies.  Wall-clock pacing is a separate concern (a :class:`~servo.runtime.pacing.Pacer`:
``start()`` right before the first tick, ``wait(k)`` before tick ``k``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Protocol, Sequence

from servo.runtime.driver import Driver
from servo.runtime.durations import Durations
from servo.runtime.pacing import Pacer


@dataclass
class Task:
    """``fn(k)`` every ``every`` ticks, at ticks where ``(k - offset) % every == 0``."""

    name: str
    every: int
    fn: Callable[[int], None]
    offset: int = 0

    def __post_init__(self) -> None:
        if self.every < 1:
            raise ValueError(f"task {self.name}: every must be >= 1")

    def due(self, k: int) -> bool:
        return (k - self.offset) % self.every == 0


@dataclass
class TickData:
    """What the tasks of a tick share: sample, reference, excitation, command."""

    x: float = math.nan
    v: float = math.nan
    r: float = 0.0
    u_exc: float = 0.0
    u: float = 0.0


class ControllerLike(Protocol):
    def start(self, x: float, v: float, u_now: float) -> None: ...
    def tick(self, x: float, v: float, r: float, u_exc: float) -> float: ...


@dataclass
class Scheduler:
    """Steps ``controller`` against ``driver`` tick by tick with multi-rate tasks."""

    driver: Driver
    controller: ControllerLike
    before: Sequence[Task] = ()
    after: Sequence[Task] = ()
    data: TickData = field(default_factory=TickData)
    pacer: Pacer | None = None

    def run(self, k0: int, n: int, start: bool = True, timing: Durations | None = None) -> None:
        """Run ticks ``k0 .. k0+n-1``.  ``start``: the controller takes over at ``k0``.
        ``timing``, if given, receives each tick's compute time in ns (read to the end of
        the last task), for overrun accounting; it is folded every block and on exit."""
        driver, ctl, data = self.driver, self.controller, self.data
        before, after, pacer = tuple(self.before), tuple(self.after), self.pacer
        clock = time.perf_counter_ns
        tbuf = timing.buf if timing is not None else None
        tsize = 0 if tbuf is None else tbuf.shape[0]
        j = 0  # durations in tbuf not yet folded
        try:
            for k in range(k0, k0 + n):
                if pacer is not None:
                    pacer.wait(k)
                t0 = clock()
                x, v = driver.read()
                data.x = x
                data.v = v
                if start and k == k0:
                    ctl.start(x, v, driver.applied_current)
                for task in before:
                    if (k - task.offset) % task.every == 0:
                        task.fn(k)
                u = ctl.tick(x, v, data.r, data.u_exc)
                driver.write(u)
                data.u = u
                for task in after:
                    if (k - task.offset) % task.every == 0:
                        task.fn(k)
                if tbuf is not None:
                    tbuf[j] = clock() - t0
                    j += 1
                    if j == tsize:
                        timing.fold(j)
                        j = 0
        finally:
            if timing is not None:
                timing.fold(j)

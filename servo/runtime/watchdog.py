"""Instability is a fault: the run's watchdog, one mechanism for every driver and path.

A loop that diverges, or limit-cycles against the current limit, or drives the arm out of
its stroke, must not run to the end and print a normal summary.  The watchdog reads the
rows the run logs (:data:`kernels.compose.LOG_COLUMNS`: the position ``x`` and the
current command ``u``), in chunks, before the log hands them to its journal, so it sees
what the tick path (the simulated drive or a board over the link) and the compiled fast
path record alike, and stops the run with :class:`~servo.errors.UnstableLoop` (exit 3,
one line; :func:`servo.runtime.loop.run_closed_loop` puts the drive in its safe state and
keeps what was recorded) when

* the position leaves ``+-run.fault_position`` (default: 95 % of ``drive.stroke``, short
  of the hard stops): a diverging loop or one that sits at a stop;
* the current command sits at its limit (``controller.current_limit`` or
  ``drive.current_limit``, whichever is lower) on more than ``run.fault_limit_share`` of
  the ticks of any ``run.fault_window_s`` window: a loop saturated for good, or
  limit-cycling between the limits.

A non-finite state is the driver's own fault (:meth:`servo.runtime.simdriver.SimDriver.check_state`).
A limit cycle that stays inside the current limit and the stroke is not caught here.
"""
from __future__ import annotations

import numpy as np

from kernels.compose import LOG_COLUMNS
from kernels.watch import CARRY_SIZE, first_outside, first_over_share
from servo.config import Config
from servo.errors import UnstableLoop

#: Rows the tick path logs between two looks (a look costs a few microseconds).
CHECK_ROWS = 256


class Watchdog:
    """Looks at a run's log rows as they are written: :meth:`look` before every hand-over
    of the log's block (and every :data:`CHECK_ROWS` rows on the tick path)."""

    def __init__(self, cfg: Config):
        r = cfg.run
        self.dt_row = cfg.dt * r.log_every
        self.position = r.fault_position if r.fault_position > 0 else 0.95 * cfg.drive.stroke
        self.limit = min(cfg.controller.current_limit, cfg.drive.current_limit) * (1.0 - 1e-9)
        self.share = r.fault_limit_share
        self.window = max(1, int(round(r.fault_window_s / self.dt_row)))
        self.ix, self.iu = LOG_COLUMNS.index("x"), LOG_COLUMNS.index("u")
        self.start = 0  # first row of the log's block not looked at yet
        self.ring = np.zeros(self.window, dtype=np.uint8)  # at-limit flags of the latest window of rows (kernels.watch)
        self.carry = np.zeros(CARRY_SIZE, dtype=np.int64)
        self.carry[3:5] = -1  # no row outside, none over the share (kernels.watch.watch_row)
        #: what the compiled loop tests each row against: position, limit, most flags in a window
        self.watch = np.array([self.position, self.limit, self.share * self.window if self.share < 1.0 else np.inf])

    def look(self, log) -> None:
        """Check the rows ``log.data[start:log.rows]``; raises :class:`UnstableLoop`."""
        rows = np.ascontiguousarray(log.data[self.start : log.rows], dtype=np.float64)
        self.start = log.rows
        if rows.shape[0] == 0:
            return
        i = first_outside(rows, self.ix, self.position)
        if i >= 0:
            self._outside(rows[i])
        if self.share >= 1.0:
            return
        j, count = first_over_share(rows, self.iu, self.limit, self.ring, self.carry, self.share * self.window)
        if j >= 0:
            self._over_share(count, rows[-1, 1])

    def looked(self, log) -> None:
        """The compiled loop has tested the rows ``log.data[start:log.rows]`` as it logged
        them (:func:`kernels.watch.watch_row` on :attr:`watch`, :attr:`ring`,
        :attr:`carry`): raise as :meth:`look` would have on them."""
        i, j = self.carry[3], self.carry[4]
        if i >= 0:
            self._outside(log.data[i])
        if j >= 0:
            self._over_share(int(self.carry[5]), log.data[log.rows - 1, 1])
        self.start = log.rows

    def _outside(self, row) -> None:
        x = row[self.ix]
        raise UnstableLoop(f"unstable loop: the position reached {x * 1e3:.3f} mm at t = {row[1]:.4f} s, "
                           f"outside +-{self.position * 1e3:.4g} mm (run.fault_position); run stopped, drive set "
                           "to zero current")  # fmt: skip

    def _over_share(self, count: int, t: float) -> None:
        raise UnstableLoop(f"unstable loop: the current command sat at its limit (+-{self.limit:.4g} A) on "
                           f"{100 * count / self.window:.0f} % of a {self.window * self.dt_row:g} s "
                           f"window ending near t = {t:.4f} s (run.fault_limit_share = {self.share:g}); run "
                           "stopped, drive set to zero current")  # fmt: skip

    def flush(self, log, looked: bool = False) -> None:
        """Look at what is left of the block (``looked``: the compiled loop did,
        :meth:`looked`), then let the log hand it over."""
        if looked:
            self.looked(log)
        else:
            self.look(log)
        log.maybe_flush()
        self.start = min(self.start, log.rows)

    def next_look(self, log) -> int:
        """The value of ``log.rows`` at which the tick path calls :meth:`flush` next: after
        :data:`CHECK_ROWS` rows, or when the log's block is full.  The loop compares its row
        count with it after each logged row (an integer comparison, where a method call per
        tick cost ~0.2 us of a ~4 us tick)."""
        return min(self.start + CHECK_ROWS, getattr(log, "block_rows", 1 << 62))

    def maybe_look(self, log) -> None:
        """On the tick path, after each logged row: look every :data:`CHECK_ROWS` rows and
        before the log's block is handed over."""
        if log.rows >= self.next_look(log):
            self.flush(log)


__all__ = ["CHECK_ROWS", "Watchdog"]

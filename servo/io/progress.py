"""Progress of a long job on stderr: what it is doing, done/total and an ETA.

A job reports through the *current* reporter: library code calls :func:`stage`,
:func:`advance`, :func:`each` and :func:`watch`, which do nothing unless the command line
installed a :class:`Reporter` with :func:`reporting` (a context variable, so nothing is
global: a notebook, a test or a Dask worker that calls the same job prints nothing).
``--quiet`` installs :data:`QUIET`.

What a :class:`Reporter` writes, and when:

* **nothing** during the first :data:`DELAY_S` seconds (a quick job prints no progress)
  and **never on stdout**, which carries the command's summary;
* on a terminal (``stream.isatty()``): **one line rewritten in place** at most every
  :data:`TTY_EVERY_S` seconds, cut to the terminal's width and **cleared** when the job
  ends, so the summary starts on a clean line;
* otherwise (a pipe, a log file, CI): **plain lines**, at most one every
  :data:`EVERY_S` seconds and only when the stage or its count changed (or every
  :data:`HEARTBEAT_S` seconds while a long stage runs), then ``done in N s``.

A line reads ``servo diagnose: candidate terms, round 2 5/14 (hysteresis), 8.1 s, ~12 s
left``: the command, the stage, done/total with their unit, what is being done now,
the time since the job started and, when the stage has a total, its estimated time left
(at the stage's rate since its first item was done, so that a start-up does not count).  The lines are written by a thread of the reporter that wakes
at that cadence: the job itself only updates counters (no I/O, no formatting), so a tick
loop is not slowed by its reporting.
"""
from __future__ import annotations

import contextvars
import math
import shutil
import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterable, Iterator, TypeVar

#: seconds before the first line (a job shorter than this prints nothing)
DELAY_S = 2.0
#: plain lines: at most one every this many seconds
EVERY_S = 2.0
#: plain lines: a line at least this often while a stage runs, even without a change
HEARTBEAT_S = 15.0
#: terminal: the line is redrawn at most this often
TTY_EVERY_S = 0.5

T = TypeVar("T")


def _secs(s: float) -> str:
    if s < 10:
        return f"{s:.1f} s"
    if s < 120:
        return f"{s:.0f} s"
    return f"{s / 60:.0f} min"


class Quiet:
    """A reporter that reports nothing (``--quiet``, and every library call by default)."""

    def stage(self, what: str, total: int | None = None, unit: str = "") -> None:
        pass

    def advance(self, n: int = 1, detail: str | None = None) -> None:
        pass

    def update(self, done: int, detail: str | None = None) -> None:
        pass

    def each(self, items: Iterable[T], what: str, name: Callable[[T], str] | None = None, unit: str = "") -> Iterator[T]:
        return iter(items)

    @contextmanager
    def watch(self, done: Callable[[], int]):
        yield self

    def note(self, text: str) -> None:
        pass

    def rebase(self) -> None:
        pass

    def close(self, failed: bool = False) -> None:
        pass


QUIET = Quiet()


class Reporter(Quiet):
    """Progress of one command (``label``, e.g. ``"servo run"``) on ``stream`` (default
    stderr); see the module doc.  ``tty``: force the terminal or the plain form (default:
    ``stream.isatty()``).  ``delay_s``/``every_s``: the module's defaults when None.
    ``thread=False``: no thread of its own; lines are written only when :meth:`emit` is
    called (tests, with their own ``clock``)."""

    def __init__(self, label: str, stream=None, tty: bool | None = None, delay_s: float | None = None,
                 every_s: float | None = None, clock: Callable[[], float] = time.monotonic,
                 thread: bool = True):  # fmt: skip
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        if tty is None:
            isatty = getattr(self.stream, "isatty", None)
            tty = bool(isatty()) if isatty is not None else False
        self.tty = tty
        self.delay_s = DELAY_S if delay_s is None else delay_s
        self.every_s = (TTY_EVERY_S if tty else EVERY_S) if every_s is None else every_s
        self.clock = clock
        self.t0 = clock()
        self.what, self.total, self.unit, self.done, self.detail = "", None, "", 0, None
        self.stage_t0 = self.t0
        self._first: tuple[float, int] | None = None
        self.lines = 0  # lines written (plain) or redraws (terminal)
        self._drawn = False  # a terminal line is showing
        self._last_key = None
        self._last_emit = -math.inf
        self._done_fn: Callable[[], int] | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closed = False
        self._threaded = thread

    # ------------------------------------------------------------ the job's side

    def stage(self, what: str, total: int | None = None, unit: str = "") -> None:
        """A new stage: ``what`` is being done, ``total`` items of ``unit`` (None: no count)."""
        with self._lock:
            self.what, self.total, self.unit, self.done, self.detail = what, total, unit, 0, None
            self.stage_t0 = self.clock()
            self._first = None
        self._start()

    def advance(self, n: int = 1, detail: str | None = None) -> None:
        """``n`` more items of the stage done; ``detail``: what is being done now."""
        with self._lock:
            self.done += n
            self._note()
            if detail is not None:
                self.detail = detail

    def update(self, done: int, detail: str | None = None) -> None:
        """``done`` items of the stage done so far."""
        with self._lock:
            self.done = done
            self._note()
            if detail is not None:
                self.detail = detail

    def each(self, items: Iterable[T], what: str, name: Callable[[T], str] | None = None, unit: str = "") -> Iterator[T]:
        """Iterate over ``items`` as one stage: done/total counts the items finished, the
        detail names the one in hand (``name(item)``, default ``str``)."""
        items = list(items)
        self.stage(what, len(items), unit)
        name = name or str
        for i, item in enumerate(items):
            self.update(i, name(item))
            yield item
        self.update(len(items))

    @contextmanager
    def watch(self, done: Callable[[], int]):
        """While the block runs, the stage's count is ``done()``, read by the reporter's
        thread at its cadence (for a loop that cannot call back: a run reads the rows its
        log has recorded)."""
        with self._lock:
            self._done_fn = done
        self._start()
        try:
            yield self
        finally:
            with self._lock:
                self._done_fn = None
                try:
                    self.done = int(done())
                except Exception:  # noqa: BLE001  (a counter that cannot be read any more: keep the last)
                    pass

    def rebase(self) -> None:
        """Count the time left's rate from now: what was done so far is not a rate (the
        first results of workers that ran side by side since the start, which come back
        together)."""
        with self._lock:
            if self.done > 0:
                self._first = (self.clock(), self.done)

    def note(self, text: str) -> None:
        """Write ``<label>: <text>`` on a line of its own now (something to act on while
        the job runs, such as where to watch it), whatever the cadence."""
        with self._lock:
            if self._closed:
                return
            if self._drawn:
                self._write("\r\x1b[K")
                self._drawn = False
            self._write(f"{self.label}: {text}\n")

    def close(self, failed: bool = False) -> None:
        """Stop the thread; clear the terminal line, or write the last plain line
        (``done in N s``; nothing when the job ``failed``: its error line follows)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        with self._lock:
            elapsed = self.clock() - self.t0
            if self.tty:
                if self._drawn:
                    self._write("\r\x1b[K")
                    self._drawn = False
            elif self.lines and not failed:
                self._write(f"{self.label}: done in {_secs(elapsed)}\n")

    def _note(self) -> None:
        """The first count of the stage (with the lock held): the rate after it is the
        ETA's, so a start-up (a cluster starting, kernels loading) does not inflate it."""
        if self._first is None and self.done > 0:
            self._first = (self.clock(), self.done)

    # ------------------------------------------------------------ the reporter's thread

    def _start(self) -> None:
        if self._thread is None and self._threaded and not self._closed:
            self._thread = threading.Thread(target=self._run, name=f"progress {self.label}", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        period = min(self.every_s, 0.5) if self.every_s > 0 else 0.01
        while not self._stop.wait(period):
            self.emit()

    def line(self) -> tuple[str, tuple]:
        """The current line, and what in it counts as a change (stage, count, detail)."""
        now = self.clock()
        parts = [self.what] if self.what else []
        if self.total is not None:
            parts.append(f"{self.done}/{self.total}" + (f" {self.unit}" if self.unit else ""))
        text = f"{self.label}: " + " ".join(parts)
        if self.detail:
            text += f" ({self.detail})"
        text += f", {_secs(now - self.t0)}"
        t1, d1 = self._first or (now, self.done)
        if self.total and d1 < self.done < self.total:  # not from the first count: it includes a start-up
            left = (now - t1) / (self.done - d1) * (self.total - self.done)
            text += f", ~{_secs(left)} left"
        return text, (self.what, self.done, self.total, self.detail)

    def emit(self, now: float | None = None) -> bool:
        """Write the current line if the cadence allows (called by the thread; public
        for tests).  Returns whether a line was written."""
        with self._lock:
            if self._done_fn is not None:
                try:
                    self.done = int(self._done_fn())
                    self._note()
                except Exception:  # noqa: BLE001
                    pass
            now = self.clock() if now is None else now
            if self._closed or now - self.t0 < self.delay_s or now - self._last_emit < self.every_s:
                return False
            text, key = self.line()
            if self.tty:
                width = max(shutil.get_terminal_size((100, 24)).columns - 1, 20)
                self._write("\r" + text[:width] + "\x1b[K")
                self._drawn = True
            else:
                if key == self._last_key and now - self._last_emit < HEARTBEAT_S:
                    return False
                self._write(text + "\n")
            self._last_key, self._last_emit = key, now
            self.lines += 1
            return True

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # a closed or broken stderr: progress is not worth failing the job
            pass


_CURRENT: contextvars.ContextVar[Quiet] = contextvars.ContextVar("servo_progress", default=QUIET)


def current() -> Quiet:
    """The reporter jobs report to here (:data:`QUIET` unless :func:`reporting` set one)."""
    return _CURRENT.get()


@contextmanager
def reporting(reporter: Quiet):
    """Make ``reporter`` the current one while the block runs, and close it after (its
    last line is written, or its terminal line cleared, before the block's caller prints
    anything)."""
    token = _CURRENT.set(reporter)
    try:
        yield reporter
    except BaseException:
        _CURRENT.reset(token)
        reporter.close(failed=True)
        raise
    _CURRENT.reset(token)
    reporter.close()


def stage(what: str, total: int | None = None, unit: str = "") -> None:
    """:meth:`Reporter.stage` of the current reporter."""
    _CURRENT.get().stage(what, total, unit)


def advance(n: int = 1, detail: str | None = None) -> None:
    """:meth:`Reporter.advance` of the current reporter."""
    _CURRENT.get().advance(n, detail)


def update(done: int, detail: str | None = None) -> None:
    """:meth:`Reporter.update` of the current reporter."""
    _CURRENT.get().update(done, detail)


def each(items: Iterable[T], what: str, name: Callable[[T], str] | None = None, unit: str = "") -> Iterator[T]:
    """:meth:`Reporter.each` of the current reporter."""
    return _CURRENT.get().each(items, what, name, unit)


def watch(done: Callable[[], int]):
    """:meth:`Reporter.watch` of the current reporter (a context manager)."""
    return _CURRENT.get().watch(done)


__all__ = ["DELAY_S", "EVERY_S", "HEARTBEAT_S", "QUIET", "Quiet", "Reporter", "TTY_EVERY_S", "advance", "current",
           "each", "reporting", "stage", "update", "watch"]

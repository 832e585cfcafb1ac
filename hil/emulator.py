"""The device emulator: a :class:`~hil.board.Board` served on a pseudo-terminal or TCP port.

``servo emulate`` runs :func:`serve` in its own process; tests and benchmarks may run it in
a thread (:func:`start_in_thread`, lockstep only: a spinning real-time board would starve
the host of the GIL).

* :class:`PtyTransport`: ``os.openpty()`` in raw mode; the host opens the slave path
  (printed) with pyserial.  The emulator keeps the slave open too, so a host that closes
  the port and opens it again (``servo run --compensation compare``: two sessions) finds
  the board still there; a host that vanishes is caught by the board's watchdog.
* :class:`TcpTransport`: listens on 127.0.0.1 (``socket://127.0.0.1:PORT``), one host at
  a time; a closed connection puts the drive in its safe state at once.

Modes: lockstep (the board advances when commands arrive; deterministic) or real time
(the board is the clock master: :class:`servo.runtime.pacing.Pacer` deadlines at its sample rate,
one :meth:`Board.tick` per period, the input drained without blocking every tick).
"""
from __future__ import annotations

import errno
import fcntl
import os
import select
import socket
import sys
import termios
import threading
import time
import tty
from contextlib import contextmanager

from hil.board import ACTIVE, OUT_LIMIT, Board
from servo.runtime.pacing import Pacer

PACER_CHUNK = 1 << 16
"""Ticks per :class:`Pacer` (its lateness array); the next one continues the same deadlines."""


class PtyTransport:
    """The master side of a fresh pseudo-terminal; :attr:`url` is the slave's path."""

    def __init__(self) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)  # 8-bit clean: no echo, no line editing, no CR/LF mapping
        os.set_blocking(self.master, False)
        self.url = os.ttyname(self._slave)

    def fileno(self) -> int:
        return self.master

    def recv(self) -> bytes | None:
        """Bytes received now (b'' if none); None if the host is gone (never, for a pty)."""
        try:
            return os.read(self.master, 65536)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # no slave open: cannot happen while we hold it
                return b""
            raise

    def send(self, buf: bytearray) -> None:
        """Write what the pty takes now; the rest stays in ``buf``."""
        if buf:
            try:
                del buf[: os.write(self.master, buf)]
            except BlockingIOError:
                pass

    def unread(self) -> int:
        """Bytes sent that the host has not read yet (the slave's input queue)."""
        buf = fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0")
        return int.from_bytes(buf, sys.byteorder)

    def close(self, linger_s: float = 1.0) -> None:
        """Close, after waiting up to ``linger_s`` for the host to read what was sent
        (closing the master discards it)."""
        end = time.monotonic() + linger_s
        try:
            while self.unread() and time.monotonic() < end:
                time.sleep(0.005)
        except OSError:
            pass
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class TcpTransport:
    """A listening socket on ``host:port`` (0: any free port) and at most one host."""

    def __init__(self, port: int = 0, host: str = "127.0.0.1") -> None:
        self._listener = socket.create_server((host, port))
        self._listener.setblocking(False)
        self.url = f"socket://{host}:{self._listener.getsockname()[1]}"
        self._conn: socket.socket | None = None

    def fileno(self) -> int:
        return (self._conn or self._listener).fileno()

    def recv(self) -> bytes | None:
        if self._conn is None:
            try:
                conn, _ = self._listener.accept()
            except BlockingIOError:
                return b""
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conn = conn
            return b""
        try:
            data = self._conn.recv(65536)
        except BlockingIOError:
            return b""
        except OSError:
            data = b""
        if not data:
            self._conn.close()
            self._conn = None
            return None
        return data

    def send(self, buf: bytearray) -> None:
        if not buf:
            return
        if self._conn is None:
            buf.clear()
            return
        try:
            del buf[: self._conn.send(buf)]
        except BlockingIOError:
            pass
        except OSError:
            buf.clear()  # the next recv sees the closed connection

    def close(self, linger_s: float = 0.0) -> None:
        if self._conn is not None:
            self._conn.close()
        self._listener.close()


def serve(board: Board, transport, realtime: bool = False, stop: threading.Event | None = None,
          sessions: int | None = None, poll_s: float = 0.05) -> None:  # fmt: skip
    """Run ``board`` on ``transport`` until ``stop`` is set or ``sessions`` sessions ended.

    Waiting (idle, or lockstep) is a ``select`` on the transport with a timeout of at most
    ``poll_s``, shorter when the watchdog is due.  The drive is left in its safe state.
    """
    clock = time.perf_counter_ns
    try:
        while stop is None or not stop.is_set():
            if sessions is not None and board.sessions_ended >= sessions and not board.out:
                return
            if realtime and board.state == ACTIVE:
                _run_paced(board, transport, stop)
                transport.send(board.out)
                continue
            timeout = poll_s
            due = board.watchdog_due_ns()
            if due is not None:
                timeout = min(poll_s, max(0.0, (due - clock()) / 1e9))
            fd = transport.fileno()
            ready, _, _ = select.select([fd], [fd] if board.out else [], [], timeout)
            now = clock()
            if ready:
                data = transport.recv()
                if data is None:
                    board.disconnect(now)
                elif data:
                    board.feed(data, now)
            board.check_watchdog(clock())
            transport.send(board.out)
            if len(board.out) > OUT_LIMIT:
                board.overflow()
    finally:
        board._safe()


def _run_paced(board: Board, transport, stop: threading.Event | None) -> None:
    """Real time: one board tick per period on absolute deadlines until the run ends."""
    period_s = 1.0 / board.rate
    pacer = Pacer(period_s, PACER_CHUNK)
    pacer.start()
    pacer.t0 += pacer.spin_ns  # tick 0 a moment ahead, so it is not entered "late" by construction
    base, overruns = 0, 0
    clock, recv, send, out = time.perf_counter_ns, transport.recv, transport.send, board.out
    while board.state == ACTIVE:
        j = board.k - base
        if j >= PACER_CHUNK:
            overruns += pacer.overruns
            t0 = pacer.t0 + PACER_CHUNK * pacer.period_ns
            pacer = Pacer(period_s, PACER_CHUNK)
            pacer.t0 = t0
            base += PACER_CHUNK
            j -= PACER_CHUNK
        pacer.wait(j)
        now = clock()
        data = recv()
        if data:
            board.feed(data, now)
        elif data is None:
            board.disconnect(now)
            break
        board.tick(now)
        if out:
            send(out)
            if len(out) > OUT_LIMIT:
                board.overflow()
        board.stats["overruns"] = overruns + pacer.overruns
        if stop is not None and stop.is_set():
            break
    r = pacer.report()
    if r["ticks"]:
        board.log(f"session {board.session}: pacing of the last {r['ticks']} ticks: lateness "
                  f"{r['lateness_us_p50']:.0f}/{r['lateness_us_p99']:.0f}/{r['lateness_us_max']:.0f} us "
                  f"(median/p99/max), {board.stats['overruns']} ticks started late")  # fmt: skip


def open_transport(kind: str, port: int = 0):
    """``"pty"`` or ``"tcp"`` (on 127.0.0.1:``port``)."""
    if kind == "pty":
        return PtyTransport()
    if kind == "tcp":
        return TcpTransport(port)
    raise ValueError(f"unknown transport {kind!r}")


@contextmanager
def start_in_thread(board: Board, kind: str = "pty"):
    """A lockstep emulator in a background thread (tests, benchmarks); yields its URL.
    The thread is stopped and joined, and the transport closed, on exit."""
    if not board.lockstep:
        raise ValueError("an in-thread emulator must run in lockstep")
    transport = open_transport(kind)
    stop = threading.Event()
    errors: list[BaseException] = []

    def run():
        try:
            serve(board, transport, stop=stop, poll_s=0.005)
        except BaseException as exc:  # reported to the test on exit
            errors.append(exc)

    th = threading.Thread(target=run, name="emulator", daemon=True)
    th.start()
    try:
        yield transport.url
    finally:
        stop.set()
        th.join(5.0)
        transport.close(linger_s=0.0)
    if errors:
        raise errors[0]

"""Opening a pyserial URL for the link: one-line errors, low-latency mode, waiting.

Any URL ``serial.serial_for_url`` knows works: a device path (``/dev/ttyUSB0``, a
pseudo-terminal such as ``/dev/pts/5``), ``socket://host:port``, ``loop://``, and
``faulty://...`` (:mod:`hil.faults`, registered here through pyserial's
``protocol_handler_packages``).  The port is opened non-blocking (``timeout=0``): the
driver waits with ``select`` on :meth:`fileno` where the port has one.  It is opened
exclusively (pyserial's ``exclusive=True``: an advisory ``flock`` on a device or a
pseudo-terminal), so a second host on the same board is refused at open.
"""
from __future__ import annotations

import select
import socket
import time

import serial

from servo.errors import DriverError

if "hil" not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append("hil")  # faulty:// -> hil.protocol_faulty


def open_port(url: str, baudrate: int, write_timeout_s: float):
    """Open ``url``; returns ``(port, notes)``, ``notes`` saying what low-latency mode the
    OS granted.  Raises :class:`DriverError` (one line) if it cannot be opened."""
    try:
        port = serial.serial_for_url(url, baudrate=baudrate, timeout=0, write_timeout=write_timeout_s, exclusive=True)
    except ValueError as exc:
        raise DriverError(f"link: bad port URL {url!r}: {exc}") from None
    except (serial.SerialException, OSError) as exc:
        if "exclusively lock" in str(exc):
            raise DriverError(f"link: {url} is in use by another program (its exclusive lock was refused); "
                              "one host per board") from None  # fmt: skip
        raise DriverError(f"link: cannot open {url}: {exc}") from None
    return port, low_latency(port)


def low_latency(port) -> list[str]:
    """Ask for the lowest latency the port offers: ``ASYNC_LOW_LATENCY`` on a Linux serial
    device (USB-serial adapters otherwise batch bytes for up to 16 ms), ``TCP_NODELAY`` on
    ``socket://``.  Never fails; returns one note per attempt."""
    notes = []
    sock = getattr(port, "_socket", None)  # pyserial's socket:// handler keeps it there
    if isinstance(sock, socket.socket):
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            notes.append("TCP_NODELAY set")
        except OSError as exc:
            notes.append(f"TCP_NODELAY not set ({exc})")
        return notes
    setter = getattr(port, "set_low_latency_mode", None)
    if setter is None:
        return ["low-latency mode: not offered by this port type"]
    try:
        setter(True)
        notes.append("ASYNC_LOW_LATENCY set")
    except (ValueError, OSError, NotImplementedError) as exc:
        notes.append(f"low-latency mode: not offered here ({str(exc).split(':')[0]})")
    return notes


def waiter(port):
    """A function ``wait(seconds)`` that returns when ``port`` may have bytes to read (or
    the time is up): ``select`` on its file descriptor, else a short sleep."""
    try:
        fd = port.fileno()
    except (AttributeError, NotImplementedError, OSError, ValueError):
        fd = None
    if fd is None:
        return lambda s: time.sleep(min(s, 50e-6))
    sel = select.select
    return lambda s: sel((fd,), (), (), s)

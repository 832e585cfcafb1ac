"""``faulty://``: a pyserial URL handler that wraps another port and injects link faults.

    faulty:///dev/pts/5?drop_rx=100             a device path (pty, ttyUSB...)
    faulty://?url=socket://127.0.0.1:5000&dup_tx=7

Frames are counted per direction from 1 (``rx``: board -> host, what ``read`` returns;
``tx``: host -> board, what ``write`` sends), delimited by 0x00 as on the link; a bare
0x00 (idle fill) is passed through and not counted.  Options (N a frame number):

===================  ============================================================
``corrupt_rx/tx=N``  flip bits of one byte in the middle of frame N (never into 0x00)
``drop_rx/tx=N``     frame N is lost
``dup_rx/tx=N``      frame N is delivered twice
``swap_rx/tx=N``     frame N is delivered after frame N+1 (reordering)
``silent_rx/tx=N``   frames N, N+1, ... are lost (the peer stops answering / hearing)
``vanish_rx=N``      after frame N is read, the port disappears: the inner port is
                     closed and every later read/write raises ``SerialException``
``pause_tx=N``       ``write`` of frame N first sleeps ``pause_ms`` (default 20) ms:
                     a host too slow for its deadline
===================  ============================================================

Registered for :func:`serial.serial_for_url` by :mod:`hil.port` (``hil`` is appended to
``serial.protocol_handler_packages``; :mod:`hil.protocol_faulty` is the handler module).
"""
from __future__ import annotations

import select
import time
import urllib.parse as urlparse

import serial

DIRECTED = ("corrupt", "drop", "dup", "swap", "silent")
OPTIONS = {f"{op}_{d}" for op in DIRECTED for d in ("rx", "tx")} | {"vanish_rx", "pause_tx", "pause_ms", "url"}


def corrupt_byte(b: int) -> int:
    """``b`` with bits flipped, never 0x00 (which would split the frame instead)."""
    c = b ^ 0x5A
    return c if c else 0xA5


class FrameFaults:
    """One direction of the link: splits the stream into frames, applies the faults."""

    def __init__(self, faults: dict[str, int]):
        self.faults = faults
        self.count = 0
        self._buf = bytearray()
        self._held: bytes | None = None

    def process(self, data: bytes) -> bytes:
        """The bytes to deliver for ``data`` (a partial frame waits for its end)."""
        self._buf += data
        out = bytearray()
        while True:
            i = self._buf.find(0)
            if i < 0:
                return bytes(out)
            frame = bytes(self._buf[: i + 1])
            del self._buf[: i + 1]
            if len(frame) == 1:
                out += frame
                continue
            self.count += 1
            out += self._apply(frame, self.count)

    def _apply(self, frame: bytes, n: int) -> bytes:
        f = self.faults
        if "silent" in f and n >= f["silent"]:
            return b""
        if f.get("drop") == n:
            return b""
        if f.get("corrupt") == n:
            m = len(frame) // 2
            frame = frame[:m] + bytes([corrupt_byte(frame[m])]) + frame[m + 1 :]
        if f.get("dup") == n:
            frame = frame + frame
        if f.get("swap") == n:
            self._held = frame
            return b""
        if self._held is not None:
            frame, self._held = frame + self._held, None
        return frame


def parse_url(url: str) -> tuple[str, dict[str, int]]:
    """``(inner URL, options)`` of a ``faulty://`` URL; ``SerialException`` if malformed."""
    parts = urlparse.urlsplit(url)
    if parts.scheme != "faulty":
        raise serial.SerialException(f"expected faulty://PATH?option=N... or faulty://?url=URL&option=N..., got {url!r}")
    opts: dict[str, int] = {}
    inner = parts.netloc + parts.path
    for key, values in urlparse.parse_qs(parts.query, keep_blank_values=True).items():
        if key not in OPTIONS:
            raise serial.SerialException(f"faulty://: unknown option {key!r} (one of {', '.join(sorted(OPTIONS))})")
        if key == "url":
            inner = values[0]
            continue
        try:
            opts[key] = int(values[0])
        except ValueError:
            raise serial.SerialException(f"faulty://: option {key} needs a whole number, got {values[0]!r}") from None
    if not inner:
        raise serial.SerialException("faulty://: no inner port (faulty:///dev/... or faulty://?url=...)")
    return inner, opts


class FaultySerial(serial.SerialBase):
    """A pyserial port that forwards to an inner port through :class:`FrameFaults`."""

    def open(self) -> None:
        if self.is_open:
            raise serial.SerialException("Port is already open.")
        inner_url, opts = parse_url(self.portstr)
        self.options = opts
        rx = {k[:-3]: v for k, v in opts.items() if k.endswith("_rx") and k != "vanish_rx"}
        self._vanish_at = opts.get("vanish_rx")
        if self._vanish_at is not None:
            rx["silent"] = min(rx.get("silent", self._vanish_at + 1), self._vanish_at + 1)
        self.rx = FrameFaults(rx)
        self.tx = FrameFaults({k[:-3]: v for k, v in opts.items() if k.endswith("_tx") and k != "pause_tx"})
        self._ready = bytearray()
        self._vanished = False
        self._inner = serial.serial_for_url(inner_url, baudrate=self._baudrate, timeout=0, exclusive=self._exclusive,
                                            write_timeout=self._write_timeout)  # fmt: skip
        self.is_open = True

    def _reconfigure_port(self, *args, **kwargs) -> None:
        pass

    def close(self) -> None:
        if self.is_open and not self._vanished:
            self._inner.close()
        self.is_open = False

    def fileno(self) -> int:
        self._check()
        return self._inner.fileno()

    def _check(self) -> None:
        if not self.is_open:
            raise serial.PortNotOpenError()
        if self._vanished:
            raise serial.SerialException("read failed: [Errno 5] Input/output error (faulty:// port vanished)")

    def _pull(self) -> None:
        data = self._inner.read(65536)
        if data:
            self._ready += self.rx.process(data)

    @property
    def in_waiting(self) -> int:
        self._check()
        self._pull()
        return len(self._ready)

    def read(self, size: int = 1) -> bytes:
        self._check()
        if self._vanish_at is not None and self.rx.count >= self._vanish_at and not self._ready:
            self._vanished = True  # frames up to N were delivered: now the port is gone
            self._inner.close()
            self._check()
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while True:
            self._pull()
            if self._ready or (deadline is not None and time.monotonic() >= deadline):
                break
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            select.select([self._inner.fileno()], [], [], left)
        out = bytes(self._ready[:size])
        del self._ready[:size]
        return out

    def write(self, data) -> int:
        self._check()
        data = bytes(data)
        pause = self.options.get("pause_tx")
        if pause is not None and self.tx.count < pause <= self.tx.count + data.count(0):
            time.sleep(self.options.get("pause_ms", 20) / 1e3)
        out = self.tx.process(data)
        if out:
            self._inner.write(out)
        return len(data)

    def reset_input_buffer(self) -> None:
        self._check()
        self._ready.clear()
        self._inner.reset_input_buffer()

    def reset_output_buffer(self) -> None:
        self._check()
        self._inner.reset_output_buffer()

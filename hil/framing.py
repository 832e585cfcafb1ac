"""Frames on the byte stream: COBS byte stuffing, a 0x00 delimiter, a CRC-32 trailer.

On the wire one frame is::

    COBS(body || crc32_le(body)) 0x00

* ``body``: the message (header and payload, :mod:`hil.protocol`), 1 .. :data:`MAX_BODY`
  bytes.
* ``crc32_le``: CRC-32/ISO-HDLC (``zlib.crc32``: polynomial 0x04C11DB7 reflected, init
  and final XOR 0xFFFFFFFF) of ``body``, as 4 bytes little-endian.
* COBS (Consistent Overhead Byte Stuffing, the ``cobs`` package) removes every 0x00 from
  the stuffed bytes, so 0x00 only ever delimits frames; a receiver can resynchronise
  at any delimiter after line noise.

:class:`FrameDecoder` is *total*: any byte string, fed in any chunking, yields valid
bodies and counted errors, never an exception, and its buffer never holds more than
:data:`MAX_ENCODED` bytes.
"""
from __future__ import annotations

import zlib
from struct import Struct

from cobs import cobs

MAX_BODY = 1024
"""Largest body (header + payload, CRC excluded), bytes."""
MAX_ENCODED = MAX_BODY + 4 + (MAX_BODY + 4) // 254 + 1
"""Largest stuffed frame without its delimiter, bytes (COBS adds 1 byte per 254)."""
CRC_RESIDUE = 0x2144DF1C
"""``zlib.crc32(body + crc32_le(body))`` for every body: checking a frame needs no slicing."""

_CRC = Struct("<I")
_encode = cobs.encode
_decode = cobs.decode
_DecodeError = cobs.DecodeError
_crc32 = zlib.crc32


def encode_frame(body: bytes) -> bytes:
    """The wire bytes of one frame carrying ``body`` (delimiter included)."""
    return _encode(body + _CRC.pack(_crc32(body))) + b"\x00"


class FrameDecoder:
    """Splits a received byte stream into frame bodies; counts what it rejects.

    ``feed(data)`` returns the bodies (CRC removed) of the frames completed by ``data``,
    in order.  Rejected chunks are counted, never raised:

    * ``framing_errors``: COBS decoding failed (a 0x00 where the stuffing forbids one,
      a code byte pointing past the end);
    * ``crc_errors``: stuffing fine, CRC-32 mismatch (or too short to hold a CRC);
    * ``oversize``: more than :data:`MAX_ENCODED` bytes without a delimiter; the bytes up
      to the next delimiter are discarded (the buffer stays bounded).

    Empty chunks (consecutive delimiters) are idle fill, not errors.

    ``mark_errors``: rejected chunks also appear in the returned list, in stream order, as
    the strings ``"framing"``, ``"crc"`` or ``"oversize"`` (so a receiver can tell which
    frame of a burst was the bad one).
    """

    __slots__ = ("_buf", "_skipping", "_mark", "frames", "framing_errors", "crc_errors", "oversize", "bytes")

    def __init__(self, mark_errors: bool = False) -> None:
        self._mark = mark_errors
        self._buf = bytearray()
        self._skipping = False
        self.frames = 0
        self.framing_errors = 0
        self.crc_errors = 0
        self.oversize = 0
        self.bytes = 0

    @property
    def errors(self) -> int:
        """All rejected chunks so far."""
        return self.framing_errors + self.crc_errors + self.oversize

    @property
    def buffered(self) -> int:
        """Bytes of an incomplete frame held, at most :data:`MAX_ENCODED`."""
        return len(self._buf)

    def reset(self) -> None:
        """Drop a partial frame (the counters stay)."""
        self._buf.clear()
        self._skipping = False

    def feed(self, data: bytes) -> list:
        self.bytes += len(data)
        buf = self._buf
        if 0 not in data:  # the middle of a frame
            if not self._skipping:
                buf += data
                if len(buf) > MAX_ENCODED:
                    self.oversize += 1
                    buf.clear()
                    self._skipping = True
                    return ["oversize"] if self._mark else []
            return []
        parts = data.split(b"\x00")
        tail = parts.pop()
        out = []
        for i, part in enumerate(parts):
            if i == 0:
                if self._skipping:  # the end of an oversize chunk: already counted
                    self._skipping = False
                    buf.clear()
                    continue
                if buf:
                    buf += part
                    part = bytes(buf)
                    buf.clear()
            if not part:
                continue
            if len(part) > MAX_ENCODED:
                self.oversize += 1
                if self._mark:
                    out.append("oversize")
                continue
            try:
                body = _decode(part)
            except _DecodeError:
                self.framing_errors += 1
                if self._mark:
                    out.append("framing")
                continue
            if len(body) < 5 or _crc32(body) != CRC_RESIDUE:
                self.crc_errors += 1
                if self._mark:
                    out.append("crc")
                continue
            self.frames += 1
            out.append(body[:-4])
        if tail:
            if len(tail) > MAX_ENCODED:
                self.oversize += 1
                self._skipping = True
                if self._mark:
                    out.append("oversize")
            else:
                buf += tail
        return out

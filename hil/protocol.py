"""The messages of the serial link, protocol version 3 (``docs/protocol.md`` is the spec).

Every body (what :mod:`hil.framing` stuffs and checksums) starts with a 4-byte header,
then a fixed, type-specific payload; all fields little-endian, floats IEEE-754 binary64::

    offset  type  field
    0       u8    version   protocol version of this frame (2)
    1       u8    type      message type; host->board 0x01..0x7F, board->host 0x81..0xFF
    2       u16   seq       frame sequence number, per direction, +1 per frame (mod 2^16)
    4       ...   payload

Host -> board: HELLO, CONFIG, START, COMMANDS, STOP.  Board -> host: INFO, READY,
SAMPLES, FAULT, STATS.  :func:`parse` is total on bodies: it returns a message or raises
:class:`Malformed` (a ``ValueError``), nothing else.  The per-tick messages (SAMPLES,
COMMANDS) also have precompiled packers/unpackers for the hot path.
"""
from __future__ import annotations

import math
from functools import lru_cache
from struct import Struct
from typing import NamedTuple

VERSION = 3
"""Version 3: CONFIG carries the seed of a simulated drive's sensor noise (32 bytes) and
READY echoes it (56 bytes); version 2: CONFIG carries the ready timeout (version 1: a
reserved field)."""
VERSION_MIN = 3
VERSION_MAX = 3
MAX_BATCH = 32
"""Samples per SAMPLES frame (and commands per COMMANDS frame), at most."""
MAX_LATENCY = 1000
"""Command latency, ticks, at most."""
MAX_WATCHDOG_US = 60_000_000
"""Watchdog (us) a board accepts at most: 60 s.  A board may hold its drive energised for
no host longer than this."""
MAX_READY_TIMEOUT_MS = 60_000
MAX_SEED = 2**63 - 1
"""The largest noise seed a CONFIG may carry (``run.seed``'s range)."""
"""Ready timeout (ms) a board accepts at most: 60 s."""
DEFAULT_READY_TIMEOUT_MS = 2_000
"""The ready timeout (ms) of ``link.ready_timeout_s``'s default: 2 s."""
MAX_TEXT = 200
"""Bytes of UTF-8 text in a FAULT message (INFO name: 32)."""
TICK_MOD = 1 << 32
SEQ_MOD = 1 << 16

# message types
HELLO, CONFIG, START, COMMANDS, STOP = 0x01, 0x02, 0x03, 0x04, 0x05
INFO, READY, SAMPLES, FAULT, STATS = 0x81, 0x82, 0x84, 0x85, 0x86
TYPE_NAMES = {HELLO: "HELLO", CONFIG: "CONFIG", START: "START", COMMANDS: "COMMANDS", STOP: "STOP",
              INFO: "INFO", READY: "READY", SAMPLES: "SAMPLES", FAULT: "FAULT", STATS: "STATS"}  # fmt: skip

# INFO capability bits
CAP_VELOCITY = 0x0001  # samples carry a measured velocity (else v is NaN)
CAP_LOCKSTEP = 0x0002  # the board advances when commands arrive (emulator), not on its clock
CAP_CURRENT = 0x0004  # samples carry the applied current
CAP_LOOP = 0x0008  # the board runs the loop itself (LOOP, REFS, GAINS; docs/protocol.md section 9)

# SAMPLES status bits
STATUS_HELD = 0x01  # a tick of this frame ran on the previous current: its command was late

# FAULT codes
FAULT_WATCHDOG = 1
FAULT_DEADLINE = 2
FAULT_CORRUPT = 3
FAULT_SEQUENCE = 4
FAULT_COMMAND = 5
FAULT_CONFIG = 6
FAULT_VERSION = 7
FAULT_PROTOCOL = 8
FAULT_OVERFLOW = 9
FAULT_INTERNAL = 10
FAULT_NAMES = {FAULT_WATCHDOG: "watchdog", FAULT_DEADLINE: "deadline missed", FAULT_CORRUPT: "corrupt frame",
               FAULT_SEQUENCE: "sequence error", FAULT_COMMAND: "bad command", FAULT_CONFIG: "config rejected",
               FAULT_VERSION: "version mismatch", FAULT_PROTOCOL: "protocol error",
               FAULT_OVERFLOW: "output overflow", FAULT_INTERNAL: "internal error"}  # fmt: skip

STATS_FIELDS = (
    "ticks",  # ticks run since START
    "rx_frames",  # valid frames received
    "tx_frames",  # frames sent
    "crc_errors",  # received chunks with a CRC mismatch
    "framing_errors",  # received chunks that are not valid COBS, or oversize
    "malformed",  # valid frames with a bad version, type or length
    "seq_dropped",  # sequence gaps: frames that never came
    "seq_repeated",  # frames that repeated the previous sequence number (duplicated)
    "seq_reordered",  # frames out of order (older than expected, or ahead of one already queued)
    "missed_deadlines",  # ticks whose command was not there in time (real-time)
    "late_commands",  # commands that arrived after their tick
    "watchdog_trips",  # watchdog expiries
    "faults",  # faults raised (each sends a FAULT frame)
    "overruns",  # ticks the board itself started late (emulator pacing)
)

HEADER = Struct("<BBH")
_HELLO = Struct("<BBHIBBH")  # header, nonce u32, v_min u8, v_max u8, reserved u16
_INFO = Struct("<BBHIBBHddHH")  # header, nonce, v_min, v_max, caps, rate, current limit, max batch, max latency
_CONFIG = Struct("<BBHBBHIHHdQ")  # header, version, batch, latency, watchdog_us, late_limit, ready_timeout_ms, rate, seed
_READY = Struct("<BBHBBHIHHdQddd")  # CONFIG fields echoed, then x, v, i of tick 0
_CMD_HEAD = Struct("<BBHIBBH")  # header, tick0 u32, count u8, reserved u8, reserved u16
_SMP_HEAD = Struct("<BBHIBBH")  # header, tick0 u32, count u8, status u8, missed u16
_FAULT = Struct("<BBHHHI")  # header, code u16, reserved u16, tick u32
_STATS = Struct("<BBH" + "I" * len(STATS_FIELDS))
_EMPTY = HEADER


class Malformed(ValueError):
    """A body whose CRC was good but whose content is not a valid message."""


class Hello(NamedTuple):
    nonce: int
    v_min: int
    v_max: int


class Info(NamedTuple):
    nonce: int
    v_min: int
    v_max: int
    caps: int
    sample_rate_hz: float
    current_limit: float
    max_batch: int
    max_latency: int
    name: str


class ConfigMsg(NamedTuple):
    version: int
    batch: int
    latency: int
    watchdog_us: int
    late_limit: int
    sample_rate_hz: float
    ready_timeout_ms: int = DEFAULT_READY_TIMEOUT_MS
    seed: int = 0
    """The seed of a simulated drive's sensor noise (``run.seed``); a board with a real
    drive ignores it."""


class Ready(NamedTuple):
    config: ConfigMsg
    x: float
    v: float
    i: float


class Start(NamedTuple):
    pass


class Stop(NamedTuple):
    pass


class Commands(NamedTuple):
    tick0: int
    values: tuple


class Samples(NamedTuple):
    tick0: int
    status: int
    missed: int
    values: tuple  # x0, v0, i0, x1, v1, i1, ...


class Fault(NamedTuple):
    code: int
    tick: int
    text: str

    def describe(self) -> str:
        return f"{FAULT_NAMES.get(self.code, f'fault {self.code}')} at tick {self.tick}: {self.text}"


class Stats(NamedTuple):
    counters: dict


# ------------------------------------------------------------------------- encoding


def _text(s: str, limit: int) -> bytes:
    b = s.encode("utf-8")[:limit]
    return b.decode("utf-8", "ignore").encode("utf-8")  # never cut a character in half


def hello(seq: int, nonce: int, v_min: int = VERSION_MIN, v_max: int = VERSION_MAX) -> bytes:
    return _HELLO.pack(VERSION, HELLO, seq, nonce, v_min, v_max, 0)


def info(seq: int, m: Info) -> bytes:
    return _INFO.pack(VERSION, INFO, seq, m.nonce, m.v_min, m.v_max, m.caps, m.sample_rate_hz, m.current_limit,
                      m.max_batch, m.max_latency) + _text(m.name, 32)  # fmt: skip


def config(seq: int, m: ConfigMsg) -> bytes:
    return _CONFIG.pack(VERSION, CONFIG, seq, m.version, m.batch, m.latency, m.watchdog_us, m.late_limit,
                        m.ready_timeout_ms, m.sample_rate_hz, m.seed)  # fmt: skip


def ready(seq: int, m: Ready) -> bytes:
    c = m.config
    return _READY.pack(VERSION, READY, seq, c.version, c.batch, c.latency, c.watchdog_us, c.late_limit,
                       c.ready_timeout_ms, c.sample_rate_hz, c.seed, m.x, m.v, m.i)  # fmt: skip


def start(seq: int) -> bytes:
    return _EMPTY.pack(VERSION, START, seq)


def stop(seq: int) -> bytes:
    return _EMPTY.pack(VERSION, STOP, seq)


def fault(seq: int, code: int, tick: int, text: str) -> bytes:
    return _FAULT.pack(VERSION, FAULT, seq, code, 0, tick % TICK_MOD) + _text(text, MAX_TEXT)


def stats(seq: int, counters: dict) -> bytes:
    return _STATS.pack(VERSION, STATS, seq, *(min(int(counters.get(f, 0)), 0xFFFFFFFF) for f in STATS_FIELDS))


@lru_cache(maxsize=2 * MAX_BATCH + 2)
def commands_struct(count: int) -> Struct:
    """Header + COMMANDS payload with ``count`` commands (f64, A)."""
    return Struct(_CMD_HEAD.format + "d" * count)


@lru_cache(maxsize=2 * MAX_BATCH + 2)
def samples_struct(count: int) -> Struct:
    """Header + SAMPLES payload with ``count`` samples of (x m, v m/s, i A), f64 each."""
    return Struct(_SMP_HEAD.format + "d" * (3 * count))


def commands(seq: int, tick0: int, values) -> bytes:
    """COMMANDS: ``values[i]`` (A) is the command computed from sample ``tick0 + i``."""
    return commands_struct(len(values)).pack(VERSION, COMMANDS, seq, tick0 % TICK_MOD, len(values), 0, 0, *values)


def samples(seq: int, tick0: int, status: int, missed: int, values) -> bytes:
    """SAMPLES: ``values`` = x, v, i of ticks ``tick0, tick0+1, ...``."""
    n = len(values) // 3
    return samples_struct(n).pack(VERSION, SAMPLES, seq, tick0 % TICK_MOD, n, status, min(missed, 0xFFFF), *values)


# ------------------------------------------------------------------------- decoding


def header(body: bytes) -> tuple[int, int, int]:
    """``(version, type, seq)`` of a body; :class:`Malformed` if shorter than a header."""
    if len(body) < HEADER.size:
        raise Malformed(f"{len(body)}-byte frame is shorter than its header")
    return HEADER.unpack_from(body)


def _exact(body: bytes, s: Struct, name: str) -> tuple:
    if len(body) != s.size:
        raise Malformed(f"{name} frame of {len(body)} bytes, expected {s.size}")
    return s.unpack(body)


def _at_least(body: bytes, s: Struct, name: str, extra: int) -> tuple:
    if not s.size <= len(body) <= s.size + extra:
        raise Malformed(f"{name} frame of {len(body)} bytes, expected {s.size}..{s.size + extra}")
    return s.unpack_from(body)


def _decode_text(b: bytes) -> str:
    return b.decode("utf-8", "replace")


def parse(body: bytes):
    """``(type, seq, message)`` of a body of protocol version :data:`VERSION`.

    Raises :class:`Malformed` for a wrong version, an unknown type, a wrong length or an
    inconsistent count; never anything else.
    """
    version, kind, seq = header(body)
    if version != VERSION and kind not in (HELLO, INFO):  # HELLO/INFO layouts are frozen across versions
        raise Malformed(f"protocol version {version} frame (this end speaks {VERSION_MIN}..{VERSION_MAX})")
    if kind == SAMPLES:
        if len(body) < _SMP_HEAD.size:
            raise Malformed("SAMPLES frame shorter than its header")
        _, _, _, tick0, n, status, missed = _SMP_HEAD.unpack_from(body)
        if not 1 <= n <= MAX_BATCH:
            raise Malformed(f"SAMPLES frame with {n} samples (1..{MAX_BATCH})")
        v = _exact(body, samples_struct(n), "SAMPLES")
        return kind, seq, Samples(tick0, status, missed, v[7:])
    if kind == COMMANDS:
        if len(body) < _CMD_HEAD.size:
            raise Malformed("COMMANDS frame shorter than its header")
        _, _, _, tick0, n, _, _ = _CMD_HEAD.unpack_from(body)
        if not 1 <= n <= MAX_BATCH:
            raise Malformed(f"COMMANDS frame with {n} commands (1..{MAX_BATCH})")
        v = _exact(body, commands_struct(n), "COMMANDS")
        return kind, seq, Commands(tick0, v[7:])
    if kind == HELLO:
        v = _exact(body, _HELLO, "HELLO")
        return kind, seq, Hello(v[3], v[4], v[5])
    if kind == INFO:
        v = _at_least(body, _INFO, "INFO", 32)
        return kind, seq, Info(*v[3:], name=_decode_text(body[_INFO.size:]))
    if kind == CONFIG:
        v = _exact(body, _CONFIG, "CONFIG")
        return kind, seq, ConfigMsg(v[3], v[4], v[5], v[6], v[7], v[9], v[8], v[10])
    if kind == READY:
        v = _exact(body, _READY, "READY")
        return kind, seq, Ready(ConfigMsg(v[3], v[4], v[5], v[6], v[7], v[9], v[8], v[10]), v[11], v[12], v[13])
    if kind == START:
        _exact(body, _EMPTY, "START")
        return kind, seq, Start()
    if kind == STOP:
        _exact(body, _EMPTY, "STOP")
        return kind, seq, Stop()
    if kind == FAULT:
        v = _at_least(body, _FAULT, "FAULT", MAX_TEXT)
        return kind, seq, Fault(v[3], v[5], _decode_text(body[_FAULT.size:]))
    if kind == STATS:
        v = _exact(body, _STATS, "STATS")
        return kind, seq, Stats(dict(zip(STATS_FIELDS, v[3:])))
    raise Malformed(f"unknown message type 0x{kind:02x}")


def encode(seq: int, msg) -> bytes:
    """The body of any message (the inverse of :func:`parse`)."""
    if isinstance(msg, Samples):
        return samples(seq, msg.tick0, msg.status, msg.missed, msg.values)
    if isinstance(msg, Commands):
        return commands(seq, msg.tick0, msg.values)
    if isinstance(msg, Hello):
        return hello(seq, msg.nonce, msg.v_min, msg.v_max)
    if isinstance(msg, Info):
        return info(seq, msg)
    if isinstance(msg, ConfigMsg):
        return config(seq, msg)
    if isinstance(msg, Ready):
        return ready(seq, msg)
    if isinstance(msg, Start):
        return start(seq)
    if isinstance(msg, Stop):
        return stop(seq)
    if isinstance(msg, Fault):
        return fault(seq, msg.code, msg.tick, msg.text)
    if isinstance(msg, Stats):
        return stats(seq, msg.counters)
    raise TypeError(f"not a message: {msg!r}")


def classify_seq(received: int, expected: int, queued=()) -> tuple[str, str]:
    """A sequence error: ``(counter, explanation)``.  ``queued``: sequence numbers of the
    frames received after this one and not yet processed (the missing frame among them
    means reordering, not a drop)."""
    d = seq_delta(received, expected)
    if d == -1:
        return "seq_repeated", "a repeated frame (duplicated)"
    if d < -1:
        return "seq_reordered", "an older frame (reordered)"
    if expected in queued:
        return "seq_reordered", "the expected frame came after a later one (reordered)"
    return "seq_dropped", f"{d} frame(s) missing (dropped)"


def seq_delta(received: int, expected: int) -> int:
    """``received - expected`` modulo 2^16, in -32768..32767: 0 in order, > 0 frames
    skipped, -1 a repeat of the previous frame, < -1 an older frame."""
    d = (received - expected) % SEQ_MOD
    return d - SEQ_MOD if d >= SEQ_MOD // 2 else d


def is_finite_all(values) -> bool:
    return all(math.isfinite(u) for u in values)

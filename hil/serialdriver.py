"""``SerialDriver``: the driver interface over a serial link to a DSP/VCM board.

Lifecycle (see :mod:`servo.runtime.driver`):

* ``configure``: open the pyserial URL (low-latency mode where offered), HELLO -> INFO
  (version negotiation, sample rate, capabilities), CONFIG -> READY (latency ``d``,
  batch ``b``, watchdog (:func:`board_watchdog_s`), late limit), warm up the codec.  The READY frame carries the
  board's current sample and applied current, so ``read`` while inactive and the
  controller's bumpless start work as with the simulated drive.
* ``activate``: START; the board streams samples from tick 0.
* ``read``: sample k from the current SAMPLES frame (a new frame every ``b`` ticks);
  ``write(u)``: the command of tick k, sent with the other commands of its frame when
  the frame is complete.  The board applies it at tick k+d.
* ``deactivate``: STOP (zero current); waits briefly for the board's STATS.  Never
  raises: on a dead link the board's watchdog does the rest.
* ``close``: STOP if the session begun by HELLO is not stopped yet (a host that fails or
  quits between HELLO and START leaves no board holding its current), then closes the
  port.  ``configure`` failing after HELLO closes the same way.

Strict link: a corrupt, malformed, skipped, repeated or stale frame, a FAULT from the
board, silence for ``link.timeout_s``, or the port vanishing raises
:class:`~servo.errors.DriverError` with one line saying which; the base class then puts
the drive in its safe state.  Counters are in :attr:`SerialDriver.stats`.
"""
from __future__ import annotations

import math
import os
import time
from collections import deque

import serial

from hil import protocol as P
from hil.framing import FrameDecoder, encode_frame
from hil.port import open_port, waiter
from servo.config import Config
from servo.errors import DriverError
from servo.runtime.driver import Driver, DriverInfo, DriverState

HOST_COUNTERS = ("rx_frames", "tx_frames", "rx_bytes", "tx_bytes", "crc_errors", "framing_errors", "malformed",
                 "seq_dropped", "seq_repeated", "seq_reordered", "timeouts", "board_faults", "ignored")  # fmt: skip
STOP_WAIT_S = 0.1
"""Longest wait for the board's STATS after STOP, s."""
HANDSHAKE_S = 2.0
"""Shortest wait for INFO and READY, s (the board builds its drive at CONFIG); longer if
``link.timeout_s`` is."""
LOCKSTEP_STALL_S = 0.5
"""Host stall a lockstep board's watchdog allows beyond the link's own latency, s: ten
times the default ``link.watchdog_s``; on a 2-core machine at load 4-5 a host was
descheduled for more than 50 ms (see :func:`board_watchdog_s`)."""


def board_watchdog_s(link, sample_rate_hz: float, lockstep: bool) -> float:
    """The watchdog (s) the host puts in CONFIG for a board, from ``link`` (``cfg.link``).

    A real-time board gets ``link.watchdog_s`` as configured.  A lockstep board (the
    emulator, INFO capability bit 1) waits for each COMMANDS frame anyway, so its watchdog
    guards only against a silent host and covers the link's configured round trip: the
    ``batch + command_latency_ticks`` ticks of a frame and its commands in flight at
    ``sample_rate_hz``, plus :data:`LOCKSTEP_STALL_S` for a stalled host; never below
    ``link.watchdog_s``, never above the protocol's 60 s (``MAX_WATCHDOG_US``)."""
    if not lockstep:
        return link.watchdog_s
    round_trip = (link.batch + link.command_latency_ticks) / sample_rate_hz + LOCKSTEP_STALL_S
    return min(P.MAX_WATCHDOG_US / 1e6, max(link.watchdog_s, round_trip))


class SerialDriver(Driver):
    """The board at pyserial URL ``url``, configured from ``cfg.link`` and ``cfg.run``."""

    def __init__(self, cfg: Config, url: str):
        super().__init__()
        self.cfg = cfg
        self.url = url
        link = cfg.link
        self.d = link.command_latency_ticks
        self.b = link.batch
        self.timeout_s = link.timeout_s
        self.watchdog_s = link.watchdog_s  # the board's, as sent in CONFIG (board_watchdog_s)
        self._handshake_s = max(link.timeout_s, HANDSHAKE_S)
        self.stats = dict.fromkeys(HOST_COUNTERS, 0)
        self.board_info: P.Info | None = None
        self.board_stats: dict | None = None
        self.board_fault: P.Fault | None = None
        self.version = 0
        self.notes: list[str] = []
        self._port = None
        self._dead = False
        self._session = False  # HELLO sent and no STOP since
        self._dec = FrameDecoder(mark_errors=True)
        self._frames: deque = deque()
        self._tx_seq = 0
        self._rx_seq = 0
        self._x = self._v = math.nan
        self._i = 0.0
        self._vals: tuple = ()
        self._ri = self.b  # next sample in the current frame (b: need a new frame)
        self._answered = True  # the last sample read has had its write
        self._k_frame = 0  # tick of the next SAMPLES frame
        self._cmd: list[float] = [0.0] * self.b
        self._ci = 0
        self._cmd_tick = 0
        self._smp = P.samples_struct(self.b)
        self._cmd_struct = P.commands_struct(self.b)

    # ---------------------------------------------------------------- lifecycle
    def _on_configure(self) -> DriverInfo:
        link = self.cfg.link
        self._port, self.notes = open_port(self.url, link.baudrate, self.timeout_s)
        self._wait = waiter(self._port)
        try:
            self._port.reset_input_buffer()
        except (serial.SerialException, OSError):
            pass
        nonce = int.from_bytes(os.urandom(4), "little")
        self._session = True  # from here on, every exit path sends STOP
        self._send(P.hello(0, nonce), lead=True)
        info, seq = self._await_hello_answer(nonce)
        self.board_info = info
        self._rx_seq = (seq + 1) % P.SEQ_MOD
        self.version = min(P.VERSION_MAX, info.v_max)
        if self.version < max(P.VERSION_MIN, info.v_min):
            raise DriverError(f"link: the board at {self.url} speaks protocol versions {info.v_min}..{info.v_max}, "
                              f"this host {P.VERSION_MIN}..{P.VERSION_MAX}")  # fmt: skip
        rate = self.cfg.run.sample_rate_hz
        if not math.isclose(info.sample_rate_hz, rate, rel_tol=1e-12):
            raise DriverError(f"link: the board samples at {info.sample_rate_hz:g} Hz, the config says {rate:g} Hz "
                              "(run.sample_rate_hz)")  # fmt: skip
        if self.b > info.max_batch or self.d > info.max_latency:
            raise DriverError(f"link: the board takes batches up to {info.max_batch} and latencies up to "
                              f"{info.max_latency} ticks (link.batch = {self.b}, "
                              f"link.command_latency_ticks = {self.d})")  # fmt: skip
        self.watchdog_s = board_watchdog_s(link, rate, bool(info.caps & P.CAP_LOCKSTEP))
        cfg_msg = P.ConfigMsg(self.version, self.b, self.d, max(1, int(round(self.watchdog_s * 1e6))),
                              link.late_limit_ticks, rate, max(1, int(round(link.ready_timeout_s * 1e3))),
                              self.cfg.run.seed)  # fmt: skip
        self._send(P.config(self._tx_seq, cfg_msg))
        kind, msg = self._next_message(time.perf_counter_ns() + int(self._handshake_s * 1e9), "READY")
        if kind != P.READY or msg.config != cfg_msg:
            raise DriverError(f"link: the board answered CONFIG with {P.TYPE_NAMES.get(kind, kind)}, not READY")
        self._x, self._v, self._i = msg.x, msg.v, msg.i
        self._warm_up()
        return DriverInfo(
            name=f"board '{info.name}' at {self.url}",
            sample_rate_hz=info.sample_rate_hz,
            has_velocity=bool(info.caps & P.CAP_VELOCITY),
            command_latency_ticks=self.d,
            current_limit=info.current_limit,
        )

    def _warm_up(self) -> None:
        """Run the per-tick codec paths once on scratch data (nothing compiles in the loop)."""
        body = P.samples(0, 0, 0, 0, [0.0] * (3 * self.b))
        dec = FrameDecoder()
        self._smp.unpack(dec.feed(encode_frame(body))[0])
        encode_frame(self._cmd_struct.pack(P.VERSION, P.COMMANDS, 0, 0, self.b, 0, 0, *self._cmd))

    def _on_activate(self) -> None:
        self._ri, self._answered, self._k_frame, self._ci, self._cmd_tick = self.b, True, 0, 0, 0
        self._session = True
        self._send(P.start(self._tx_seq))

    def _on_deactivate(self) -> None:
        self._stop_session()

    def _stop_session(self) -> None:
        """STOP, then collect the board's STATS for a moment.  Best effort, never raises."""
        if not self._session or self._dead or self._port is None:
            return
        self._session = False
        try:
            self._send(P.stop(self._tx_seq))
            deadline = time.perf_counter_ns() + int(min(self.timeout_s, STOP_WAIT_S) * 1e9)
            for body in self._frames_until(deadline):
                try:
                    kind, _, msg = P.parse(body)
                except P.Malformed:
                    continue
                if kind == P.STATS:
                    self.board_stats = msg.counters
                    return
                if kind == P.FAULT and self.board_fault is None:
                    self.board_fault = msg
        except Exception:  # noqa: BLE001 - a dead link must not stop the safe-state path
            return

    def _on_close(self) -> None:
        self._stop_session()  # a session configured but never activated (or a failed handshake)
        if self._port is not None:
            try:
                self._port.close()
            except Exception:  # noqa: BLE001
                pass

    @property
    def applied_current(self) -> float:
        """The current (A) the board reported applying at the latest sample."""
        return 0.0 if self.state is DriverState.CLOSED else self._i

    # ---------------------------------------------------------------- the tick path
    def _read(self) -> tuple[float, float]:
        if self.state is not DriverState.ACTIVE or not self._answered:
            return self._x, self._v  # inactive: READY's sample; or the sample not yet answered
        i = self._ri
        if i == self.b:
            self._next_samples()
            i = 0
        vals = self._vals
        j = 7 + 3 * i
        self._x = x = vals[j]
        self._v = v = vals[j + 1]
        self._i = vals[j + 2]
        self._ri = i + 1
        self._answered = False
        return x, v

    def _write(self, u: float) -> None:
        if self._answered:
            raise DriverError("serial driver: write() without a new sample read() to answer")
        self._answered = True
        cmd = self._cmd
        cmd[self._ci] = u
        self._ci += 1
        if self._ci == self.b:
            t = self._cmd_tick
            self._send(self._cmd_struct.pack(P.VERSION, P.COMMANDS, self._tx_seq, t & 0xFFFFFFFF, self.b, 0, 0, *cmd))
            self._cmd_tick = t + self.b
            self._ci = 0

    def _next_samples(self) -> None:
        """Receive the next SAMPLES frame into ``_vals`` or raise :class:`DriverError`."""
        deadline = time.perf_counter_ns() + int(self.timeout_s * 1e9)
        kind, body = self._next_body(deadline, "SAMPLES")
        if kind == P.SAMPLES and len(body) == self._smp.size:
            vals = self._smp.unpack(body)
            if vals[3] == self._k_frame & 0xFFFFFFFF and vals[4] == self.b:
                self._vals = vals
                self._k_frame += self.b
                return
        kind, msg = self._parse(body)
        if kind == P.SAMPLES:
            raise DriverError(f"link: SAMPLES frame for tick {msg.tick0} with {len(msg.values) // 3} samples, "
                              f"expected tick {self._k_frame} with {self.b}")  # fmt: skip
        raise DriverError(f"link: unexpected {P.TYPE_NAMES.get(kind, hex(kind))} frame from the board at tick "
                          f"{self._k_frame}")  # fmt: skip

    # ---------------------------------------------------------------- frames
    def _send(self, body: bytes, lead: bool = False) -> None:
        data = encode_frame(body)
        if lead:
            data = b"\x00" + data  # ends any partial frame the board holds
        try:
            self._port.write(data)
        except serial.SerialTimeoutException:
            self._dead = True
            raise DriverError(f"link: writing to {self.url} timed out after {self.timeout_s:g} s: the board is not "
                              "reading") from None  # fmt: skip
        except (serial.SerialException, OSError) as exc:
            self._dead = True
            raise DriverError(f"link: the port {self.url} vanished ({exc})") from None
        self._tx_seq = (self._tx_seq + 1) % P.SEQ_MOD
        st = self.stats
        st["tx_frames"] += 1
        st["tx_bytes"] += len(data)

    def _receive(self, deadline_ns: int, what: str) -> None:
        """Wait for bytes until ``deadline_ns`` and decode them into ``_frames``; raises on
        corrupt chunks, silence and a vanished port."""
        port, dec = self._port, self._dec
        while True:
            try:
                data = port.read(65536)
            except (serial.SerialException, OSError) as exc:
                self._dead = True
                raise DriverError(f"link: the port {self.url} vanished ({exc})") from None
            if data:
                self.stats["rx_bytes"] += len(data)
                self._frames.extend(dec.feed(data))
                if self._frames:
                    return
                continue
            left = deadline_ns - time.perf_counter_ns()
            if left <= 0:
                if what:  # not the best-effort waits of the handshake and of STOP
                    self.stats["timeouts"] += 1
                waited = self.timeout_s if what == "SAMPLES" else self._handshake_s
                raise DriverError(f"link: no {what} frame from the board at {self.url} for {waited:g} s "
                                  f"(tick {self._k_frame}): the board is silent")  # fmt: skip
            try:
                self._wait(left / 1e9)
            except (OSError, ValueError) as exc:  # the descriptor went away under select
                self._dead = True
                raise DriverError(f"link: the port {self.url} vanished ({exc})") from None

    _ERRORS = {"crc": ("crc_errors", "CRC mismatch"), "framing": ("framing_errors", "bad byte stuffing"),
               "oversize": ("framing_errors", "no delimiter within the longest frame")}  # fmt: skip

    def _next_body(self, deadline_ns: int, what: str) -> tuple[int, bytes]:
        """The next frame in sequence: ``(type, body)``."""
        if not self._frames:
            self._receive(deadline_ns, what)
        body = self._frames.popleft()
        if body.__class__ is str:  # a rejected chunk, in stream order
            key, why = self._ERRORS[body]
            self.stats[key] += 1
            raise DriverError(f"link: corrupt frame from the board at tick {self._k_frame} ({why})")
        self.stats["rx_frames"] += 1
        if len(body) < 4:
            self.stats["malformed"] += 1
            raise DriverError(f"link: a {len(body)}-byte frame from the board")
        seq = body[2] | body[3] << 8
        if seq != self._rx_seq:
            key, text = P.classify_seq(seq, self._rx_seq, [b[2] | b[3] << 8 for b in self._frames if len(b) >= 4])
            self.stats[key] += 1
            raise DriverError(f"link: board frame seq {seq}, expected {self._rx_seq} at tick {self._k_frame}: {text}")
        self._rx_seq = (seq + 1) & 0xFFFF
        return body[1], body

    def _next_message(self, deadline_ns: int, what: str):
        """The next frame in sequence, parsed; a FAULT raises."""
        _, body = self._next_body(deadline_ns, what)
        return self._parse(body)

    def _parse(self, body: bytes):
        """``(kind, message)`` of a frame body; a malformed frame or a FAULT raises."""
        try:
            kind, _, msg = P.parse(body)
        except P.Malformed as exc:
            self.stats["malformed"] += 1
            raise DriverError(f"link: malformed frame from the board at tick {self._k_frame}: {exc}") from None
        if kind == P.FAULT:
            self.stats["board_faults"] += 1
            self.board_fault = msg
            raise DriverError(f"link: board fault, {msg.describe()}; the board is at zero current")
        return kind, msg

    def _frames_until(self, deadline_ns: int):
        """Valid bodies received until ``deadline_ns``, without sequence checks (handshake
        and stop: stale frames of an earlier session may still be in flight)."""
        while True:
            if not self._frames:
                try:
                    self._receive(deadline_ns, "")
                except DriverError:  # silence or a vanished port
                    return
            while self._frames:
                body = self._frames.popleft()
                if body.__class__ is str:
                    self.stats["ignored"] += 1
                else:
                    yield body

    def _await_hello_answer(self, nonce: int) -> tuple[P.Info, int]:
        deadline = time.perf_counter_ns() + int(self._handshake_s * 1e9)
        corrupt0 = self._dec.crc_errors + self._dec.framing_errors + self._dec.oversize
        malformed = 0
        for body in self._frames_until(deadline):
            try:
                kind, seq, msg = P.parse(body)
            except P.Malformed:
                self.stats["ignored"] += 1
                malformed += 1
                continue
            if kind == P.INFO and msg.nonce == nonce:
                self.stats["rx_frames"] += 1
                return msg, seq
            self.stats["ignored"] += 1
        if self._dead:
            raise DriverError(f"link: the port {self.url} vanished during the handshake")
        corrupt = self._dec.crc_errors + self._dec.framing_errors + self._dec.oversize - corrupt0
        if corrupt or malformed:
            raise DriverError(f"link: no valid answer to HELLO from {self.url} within {self._handshake_s:g} s: "
                              f"{corrupt} corrupt and {malformed} malformed frame(s) came instead (line noise, "
                              "a wrong baud rate, or not this protocol)")  # fmt: skip
        raise DriverError(f"link: no answer to HELLO from {self.url} within {self._handshake_s:g} s: "
                          "is a board or `servo emulate` there, and not busy with another host's session?")  # fmt: skip

    # ---------------------------------------------------------------- reporting
    def report(self) -> dict:
        """What the run summary records about the link."""
        info = self.board_info
        return {
            "url": self.url,
            "board": None if info is None else info.name,
            "protocol_version": self.version,
            "lockstep": None if info is None else bool(info.caps & P.CAP_LOCKSTEP),
            "batch": self.b,
            "command_latency_ticks": self.d,
            "watchdog_s": self.watchdog_s,
            "low_latency": self.notes,
            "host": dict(self.stats),
            "board_stats": self.board_stats,
            "board_fault": None if self.board_fault is None else self.board_fault.describe(),
        }


class Sessions:
    """One serial session (driver) per run of a job, the first opened up front.

    The first driver is configured (handshake, version and rate checks) when this is
    made, so a bad URL or an absent board fails before the job writes anything; the job
    then gets it for its first run and a fresh session for each later one.  Use as a
    context manager: the first session is closed on leaving, whatever happened.

    ``make_driver(cfg, inputs)`` has the signature the jobs' ``make_driver`` takes;
    ``driver``: the driver class of every session (:class:`SerialDriver`, or
    :class:`hil.onboard.OnBoardDriver` for the loop on the board).
    Every kernel the runs call is compiled first
    (:func:`~servo.runtime.loop.compile_kernels`), before the board is put in READY: a
    board holds its drive for the ready timeout only (``link.ready_timeout_s``)."""

    def __init__(self, cfg: Config, url: str, driver: type[SerialDriver] = SerialDriver):
        from servo.runtime.loop import compile_kernels

        compile_kernels(cfg)
        self.url = url
        self.driver = driver
        self.first = driver(cfg, url)
        self.first.configure()
        self._pending = [self.first]

    def make_driver(self, cfg: Config, inputs=None) -> SerialDriver:
        return self._pending.pop() if self._pending else self.driver(cfg, self.url)

    def where(self, cfg: Config) -> str:
        """The board as a job's summary names it: its name, latency and batch (or that it
        runs the loop)."""
        if self.first.closes_loop:
            return f"{self.first.info.name} (the loop on the board, batch = {cfg.link.batch})"
        return f"{self.first.info.name} (d = {cfg.link.command_latency_ticks}, batch = {cfg.link.batch})"

    def __enter__(self) -> "Sessions":
        return self

    def __exit__(self, *exc) -> None:
        self.first.close()

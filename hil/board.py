"""The board side of the link: the protocol state machine around the simulated drive.

:class:`Board` is what the device emulator runs, and what a firmware engineer's board
must do (``docs/protocol.md``).  It has no I/O and no clock of its own: bytes go in
through :meth:`Board.feed`, frames to send collect in :attr:`Board.out`, and time comes in
as ``now_ns`` arguments, so tests drive it deterministically.

Sessions::

    IDLE --HELLO--> HELLO --CONFIG--> READY --START--> ACTIVE --STOP--> HELLO
    any fault (corrupt or out-of-sequence frame, watchdog, missed deadline, bad command)
      --> FAULTED: zero current, FAULT + STATS sent; only HELLO (or STOP) is answered.

The safe state (zero current) holds in every state but two, and those two are bounded:

* IDLE, HELLO, FAULTED: zero current.
* READY: the holding current the drive starts with (reported in READY, so that the
  controller takes over bumplessly), for at most the ready timeout of the CONFIG without
  a frame from the host; then a WATCHDOG fault.  STOP and a closed connection end it at
  once.
* ACTIVE: the host's commands, for at most the watchdog time without a COMMANDS frame.

The board protects itself from its host: a CONFIG whose watchdog, ready timeout or late
limit is beyond the documented limits (:data:`~hil.protocol.MAX_WATCHDOG_US`,
:data:`~hil.protocol.MAX_READY_TIMEOUT_MS`, a late limit longer than the watchdog) is
refused with FAULT 6, whoever sent it.

While a session is READY or ACTIVE a HELLO is refused (ignored, counted in
:attr:`Board.refused_hellos`, logged): the board belongs to the host that configured it
until that host's STOP, a fault, or its watchdog.

The drive is a :class:`~servo.runtime.simdriver.SimDriver` built afresh at every CONFIG from
the emulator's config (same seed, same disturbance array), with *no* latency of its own:
the board applies the command of sample ``k`` at tick ``k + d`` itself, and the command
of ticks ``k < d`` is the holding current the drive starts with, as in the SimDriver.
So a lockstep run through the board gives the SimDriver's bits.

* Lockstep (:meth:`advance`): the board steps as far as the commands received allow and
  sends each sample as soon as it exists; it never misses a deadline.
* Real time (:meth:`tick`, called once per period by the emulator's pacer): if the
  command due at this tick is missing, the previous current is held and the miss is
  counted; more than ``late_limit`` misses in a row is a DEADLINE fault.
* Watchdog (:meth:`check_watchdog`, both modes): no COMMANDS frame for ``watchdog_us``
  while active -> WATCHDOG fault, zero current.
"""
from __future__ import annotations

import math
from typing import Callable

from hil import protocol as P
from hil.framing import FrameDecoder, encode_frame
from servo.config import Config
from servo.runtime.driver import DriverState
from servo.scenarios import scenario_inputs
from servo.runtime.simdriver import SimDriver

IDLE, HELLO, READY, ACTIVE, FAULTED = "idle", "hello", "ready", "active", "faulted"
RING = 2048
"""Command ring size (ticks); > MAX_LATENCY + 2*MAX_BATCH."""
OUT_LIMIT = 1 << 18
"""Bytes of unsent output beyond which the host is taken as not reading (OVERFLOW)."""


class Board:
    """One emulated DSP/VCM board running the drive of ``cfg`` at ``cfg.run.sample_rate_hz``.

    ``lockstep``: advance when commands arrive (else real time: the caller paces
    :meth:`tick`).  ``log``: called with one human line per session event.
    """

    def __init__(self, cfg: Config, lockstep: bool = True, name: str = "servo emulator",
                 log: Callable[[str], None] | None = None, seed: int | None = None):  # fmt: skip
        self.cfg = cfg
        self.seed = seed
        """A fixed noise seed for every run; None: each CONFIG's (the host's ``run.seed``)."""
        self.lockstep = lockstep
        self.name = name
        self.log = log or (lambda line: None)
        self.rate = cfg.run.sample_rate_hz
        self.period_ns = int(round(1e9 / self.rate))
        self.caps = (P.CAP_VELOCITY if cfg.drive.measures_velocity else 0) | P.CAP_CURRENT
        self.caps |= P.CAP_LOCKSTEP if lockstep else 0
        self._drive_cfg = cfg.replace(link={"command_latency_ticks": 0, "batch": 1})
        self._inputs = scenario_inputs(cfg)  # the board applies their disturbance
        self.decoder = FrameDecoder(mark_errors=True)
        self.out = bytearray()
        self.stats = dict.fromkeys(P.STATS_FIELDS, 0)
        self.state = IDLE
        self.session = 0
        self.sessions_ended = 0
        self._in_session = False
        self._dec_base = (0, 0)
        self._queued = ()
        self.sim: SimDriver | None = None
        self.last_fault: P.Fault | None = None
        self.refused_hellos = 0
        self._ready_ns = 0  # when READY was sent, or the host's last frame since
        self.tx_seq = 0
        self.rx_seq = 0
        self._ring_tick = [-1] * RING
        self._ring_val = [0.0] * RING
        self._reset_run()

    # ------------------------------------------------------------------ inspection
    @property
    def applied_current(self) -> float:
        """The current (A) the amplifier applies now; 0 in the safe state."""
        return 0.0 if self.sim is None else self.sim.applied_current

    # ------------------------------------------------------------------ input
    def feed(self, data: bytes, now_ns: int) -> None:
        """Bytes received from the host."""
        dec = self.decoder
        items = dec.feed(data)
        self.stats["crc_errors"] = dec.crc_errors - self._dec_base[0]
        self.stats["framing_errors"] = dec.framing_errors + dec.oversize - self._dec_base[1]
        for i, body in enumerate(items):
            if body.__class__ is str:  # a rejected chunk, in stream order
                if self.state in (HELLO, READY, ACTIVE):
                    why = {"crc": "CRC mismatch", "framing": "bad byte stuffing", "oversize": "no delimiter"}[body]
                    self._fault(P.FAULT_CORRUPT, f"corrupt frame from the host ({why})")
                continue
            # fast path: the next in-sequence COMMANDS frame of a full batch while active
            if (body[1:2] == b"\x04" and self.state == ACTIVE and len(body) == self._cmd_size
                    and body[2] | body[3] << 8 == self.rx_seq and body[0] == P.VERSION):  # fmt: skip
                vals = self._cmd_struct.unpack(body)
                self.stats["rx_frames"] += 1
                self.rx_seq = (self.rx_seq + 1) % P.SEQ_MOD
                self._on_commands(P.Commands(vals[3], vals[7:]), now_ns)
                continue
            self._queued = [b for b in items[i + 1 :] if b.__class__ is bytes] if len(items) > 1 else ()
            self._on_frame(body, now_ns)

    def disconnect(self, now_ns: int) -> None:
        """The transport lost the host (TCP closed): safe state, session over."""
        if self.state in (READY, ACTIVE):
            self.stats["faults"] += 1
            self._safe()
            where = f"at tick {self.k}" if self.state == ACTIVE else "before START"
            self.log(f"session {self.session}: host disconnected {where}; drive at zero current")
        self._end_session()
        self.state = IDLE
        self.out.clear()
        self.decoder.reset()

    # ------------------------------------------------------------------ time
    def watchdog_due_ns(self) -> int | None:
        """When :meth:`check_watchdog` must run next (ns, the clock of ``now_ns``), or None
        while the drive is at zero current."""
        if self.state == ACTIVE:
            return self._last_cmd_ns + self._watchdog_ns
        if self.state == READY:
            return self._ready_ns + self._ready_timeout_ns
        return None

    def check_watchdog(self, now_ns: int) -> None:
        """Fault if the host has been silent too long while the drive is energised: no
        COMMANDS frame for the watchdog time while ACTIVE, no frame at all for the ready
        timeout while READY."""
        due = self.watchdog_due_ns()
        if due is None or now_ns <= due:
            return
        self.stats["watchdog_trips"] += 1
        if self.state == ACTIVE:
            ms = (now_ns - self._last_cmd_ns) / 1e6
            self._fault(P.FAULT_WATCHDOG, f"no command for {ms:.1f} ms (watchdog {self._watchdog_ns / 1e6:g} ms)")
        else:
            s = (now_ns - self._ready_ns) / 1e9
            self._fault(P.FAULT_WATCHDOG, f"no START or STOP for {s:.1f} s after READY: the host is gone")

    def advance(self, now_ns: int) -> None:
        """Lockstep: step as far as the received commands allow, sending each sample."""
        d, ring_tick, ring_val, sim = self._d, self._ring_tick, self._ring_val, self.sim
        while self.state == ACTIVE:
            k = self.k
            if not self._sampled:
                self._sample(k)
                self._sampled = True
            need = k - d
            if need < 0:
                u = self._u_start
            elif ring_tick[need % RING] == need:
                u = ring_val[need % RING]
            else:
                return
            sim.write(u)
            self.k = k + 1
            self._sampled = False
            self.stats["ticks"] += 1

    def tick(self, now_ns: int) -> None:
        """Real time: tick ``self.k`` at its deadline: apply the due command (or hold the
        last one), send the sample, step the drive to the next tick."""
        if self.state != ACTIVE:
            return
        self.check_watchdog(now_ns)
        if self.state != ACTIVE:
            return
        k = self.k
        need = k - self._d
        if need < 0:
            u = self._u_start
        elif self._ring_tick[need % RING] == need:
            u = self._ring_val[need % RING]
            self._in_a_row = 0
        else:
            if self._missed < len(self.missed_at):
                self.missed_at[self._missed] = k
            self.stats["missed_deadlines"] += 1
            self._missed += 1
            self._in_a_row += 1
            self._status |= P.STATUS_HELD
            if self._in_a_row > self._late_limit:
                self._fault(P.FAULT_DEADLINE, f"the command of tick {need} was not there at tick {k} "
                            f"({self._in_a_row} in a row): host too slow or silent")  # fmt: skip
                return
            u = self._u_last
        self._sample(k)
        self.sim.write(u)
        self._u_last = u
        self.k = k + 1
        self.stats["ticks"] += 1

    def overflow(self) -> None:
        """The transport could not send :data:`OUT_LIMIT` bytes: the host is not reading."""
        self.out.clear()
        self._fault(P.FAULT_OVERFLOW, f"more than {OUT_LIMIT} bytes unsent: the host is not reading")

    # ------------------------------------------------------------------ internals
    def _reset_run(self) -> None:
        self.k = 0  # next tick to run
        self._sampled = False
        self._sent = 0  # ticks whose sample has been sent
        self._next_cmd = 0  # tick of the next command expected
        self._batch_vals: list[float] = []
        self._batch_tick0 = 0
        self._status = 0
        self._missed = 0
        self._in_a_row = 0
        self._d = 0
        self._b = 1
        self._late_limit = 0
        self._watchdog_ns = 0
        self._ready_timeout_ns = 0
        self._last_cmd_ns = 0
        self._u_start = 0.0
        self._u_last = 0.0
        self.missed_at = [-1] * 8  # ticks of the first missed deadlines (diagnostics)
        self._cmd_struct = P.commands_struct(1)
        self._cmd_size = -1

    def _end_session(self) -> None:
        if self._in_session:
            self._in_session = False
            self.sessions_ended += 1

    def _send(self, body: bytes) -> None:
        self.out += encode_frame(body)
        self.tx_seq = (self.tx_seq + 1) % P.SEQ_MOD
        self.stats["tx_frames"] += 1

    def _sample(self, k: int) -> None:
        sim = self.sim
        x, v = sim.read()
        vals = self._batch_vals
        if not vals:
            self._batch_tick0 = k
        vals += (x, v, sim.applied_current)
        if len(vals) == 3 * self._b:
            self._send(P.samples(self.tx_seq, self._batch_tick0, self._status, self._missed, vals))
            self._sent = k + 1
            vals.clear()
            self._status = 0

    def _safe(self) -> None:
        if self.sim is not None and self.sim.state is DriverState.ACTIVE:
            self.sim.deactivate()  # SimDriver: nothing in flight, zero current

    def _fault(self, code: int, text: str) -> None:
        was = self.state
        self._safe()
        self.stats["faults"] += 1
        self.last_fault = P.Fault(code, self.k, text)
        if was in (HELLO, READY, ACTIVE):
            self._send(P.fault(self.tx_seq, code, self.k, text))
            self._send(P.stats(self.tx_seq, self.stats))
        self._end_session()
        self.state = FAULTED
        self.log(f"session {self.session}: FAULT {self.last_fault.describe()}; drive at zero current")

    def _on_frame(self, body: bytes, now_ns: int) -> None:
        try:
            kind, seq, msg = P.parse(body)
        except P.Malformed as exc:
            self.stats["malformed"] += 1
            if self.state in (HELLO, READY, ACTIVE):
                self._fault(P.FAULT_PROTOCOL, f"malformed frame from the host: {exc}")
            return
        self.stats["rx_frames"] += 1
        if kind == P.HELLO:
            self._on_hello(seq, msg)
            return
        if self.state == READY:
            self._ready_ns = now_ns  # the host is there
        if self.state in (IDLE, FAULTED):
            if kind == P.STOP and self.state == FAULTED:
                self._send(P.stats(self.tx_seq, self.stats))
            return  # no session: stale bytes of an earlier one
        if seq != self.rx_seq:
            key, what = P.classify_seq(seq, self.rx_seq, [b[2] | b[3] << 8 for b in self._queued if len(b) >= 4])
            self.stats[key] += 1
            self._fault(P.FAULT_SEQUENCE, f"host frame seq {seq}, expected {self.rx_seq}: {what}")
            return
        self.rx_seq = (seq + 1) % P.SEQ_MOD
        if kind == P.COMMANDS and self.state == ACTIVE:
            self._on_commands(msg, now_ns)
        elif kind == P.CONFIG and self.state in (HELLO, READY):
            self._on_config(msg, now_ns)
        elif kind == P.START and self.state == READY:
            self._on_start(now_ns)
        elif kind == P.STOP:
            self._on_stop()
        else:
            self._fault(P.FAULT_PROTOCOL, f"{P.TYPE_NAMES.get(kind, hex(kind))} is not expected while {self.state}")

    def _on_hello(self, seq: int, msg: P.Hello) -> None:
        if self.state in (READY, ACTIVE):
            self.refused_hellos += 1
            self.log(f"session {self.session}: a HELLO (nonce {msg.nonce:#010x}) refused: a session is "
                     f"{'running' if self.state == ACTIVE else 'configured'}; it ends with its host's STOP, "
                     "a fault or its watchdog")  # fmt: skip
            return
        self._safe()
        self._end_session()
        self.out.clear()
        self.session += 1
        self._in_session = True
        dec = self.decoder
        self._dec_base = (dec.crc_errors, dec.framing_errors + dec.oversize)
        self.stats = dict.fromkeys(P.STATS_FIELDS, 0)
        self.stats["rx_frames"] = 1
        self.state = HELLO
        self.tx_seq = 0
        self.rx_seq = (seq + 1) % P.SEQ_MOD
        self._send(P.info(self.tx_seq, P.Info(msg.nonce, P.VERSION_MIN, P.VERSION_MAX, self.caps, self.rate,
                                              self.cfg.drive.current_limit, P.MAX_BATCH, P.MAX_LATENCY, self.name)))  # fmt: skip

    def _config_problem(self, m: P.ConfigMsg) -> str | None:
        if not P.VERSION_MIN <= m.version <= P.VERSION_MAX:
            return f"protocol version {m.version} not spoken (board: {P.VERSION_MIN}..{P.VERSION_MAX})"
        if not 1 <= m.batch <= P.MAX_BATCH:
            return f"batch {m.batch} outside 1..{P.MAX_BATCH}"
        if m.latency > P.MAX_LATENCY:
            return f"latency {m.latency} ticks > {P.MAX_LATENCY}"
        if self.lockstep and m.latency < m.batch - 1:
            return f"latency {m.latency} ticks < batch - 1 = {m.batch - 1}: the link would deadlock"
        if not self.lockstep and m.latency < m.batch:
            return (f"latency {m.latency} ticks < batch {m.batch}: in real time the first command of a frame "
                    "could never arrive in time")  # fmt: skip
        if not 1 <= m.watchdog_us <= P.MAX_WATCHDOG_US:
            return f"watchdog {m.watchdog_us} us outside 1..{P.MAX_WATCHDOG_US} us"
        if not 1 <= m.ready_timeout_ms <= P.MAX_READY_TIMEOUT_MS:
            return f"ready timeout {m.ready_timeout_ms} ms outside 1..{P.MAX_READY_TIMEOUT_MS} ms"
        if m.late_limit * 1_000_000 > m.watchdog_us * self.rate:
            return (f"late limit {m.late_limit} ticks ({m.late_limit / self.rate * 1e3:g} ms) is longer than the "
                    f"watchdog ({m.watchdog_us / 1e3:g} ms)")  # fmt: skip
        if not math.isclose(m.sample_rate_hz, self.rate, rel_tol=1e-12):
            return f"the host expects {m.sample_rate_hz:g} Hz, the board samples at {self.rate:g} Hz"
        if m.seed > P.MAX_SEED:
            return f"seed {m.seed} > {P.MAX_SEED}"
        return None

    def _on_config(self, m: P.ConfigMsg, now_ns: int) -> None:
        problem = self._config_problem(m)
        if problem:
            self._fault(P.FAULT_CONFIG, problem)
            return
        self._safe()
        self._reset_run()
        self._in_session = True
        seed = m.seed if self.seed is None else self.seed  # the host's run.seed, unless fixed
        sim = SimDriver(self._drive_cfg.replace(run={"seed": seed}), self._inputs)
        sim.configure()
        sim.activate()
        self.sim = sim
        self._d, self._b, self._late_limit = m.latency, m.batch, m.late_limit
        self._cmd_struct = P.commands_struct(m.batch)
        self._cmd_size = self._cmd_struct.size
        self._watchdog_ns = m.watchdog_us * 1000
        self._ready_timeout_ns = m.ready_timeout_ms * 1_000_000
        self._u_start = self._u_last = sim.plant.u_hold
        x, v = sim.read()
        self.state = READY
        self._ready_ns = now_ns
        self._send(P.ready(self.tx_seq, P.Ready(m, x, v, sim.applied_current)))

    def _on_start(self, now_ns: int) -> None:
        self.state = ACTIVE
        self._last_cmd_ns = now_ns
        ring = self._ring_tick
        for i in range(RING):
            ring[i] = -1
        self.log(f"session {self.session}: started ({'lockstep' if self.lockstep else 'real time'}, "
                 f"d = {self._d}, batch = {self._b})")  # fmt: skip
        if self.lockstep:
            self.advance(now_ns)

    def _on_commands(self, m: P.Commands, now_ns: int) -> None:
        first = self._next_cmd
        n = len(m.values)
        if m.tick0 != first % P.TICK_MOD:
            self._fault(P.FAULT_COMMAND, f"commands for tick {m.tick0}, expected tick {first}")
            return
        if first + n > self._sent:
            self._fault(P.FAULT_COMMAND, f"commands up to tick {first + n - 1}, but samples sent only up to "
                        f"tick {self._sent - 1}")  # fmt: skip
            return
        if not P.is_finite_all(m.values):
            self._fault(P.FAULT_COMMAND, f"non-finite current command for ticks {first}..{first + n - 1}")
            return
        ring_tick, ring_val = self._ring_tick, self._ring_val
        due_passed = self.k - self._d  # real time: commands of ticks before this are late
        for i, u in enumerate(m.values):
            t = first + i
            ring_tick[t % RING] = t
            ring_val[t % RING] = u
            if t < due_passed and not self.lockstep:
                self.stats["late_commands"] += 1
        self._next_cmd = first + n
        self._last_cmd_ns = now_ns
        if self.lockstep:
            self.advance(now_ns)

    def _on_stop(self) -> None:
        was = self.state
        self._safe()
        if was == READY:
            self.log(f"session {self.session}: stopped by the host before START; drive at zero current")
        if was == ACTIVE:
            first = [t for t in self.missed_at if t >= 0]
            self.log(f"session {self.session}: stopped by the host after {self.k} ticks; drive at zero current; "
                     + ", ".join(f"{k} {v}" for k, v in self.stats.items() if v and k != "ticks")
                     + (f"; first missed deadlines at ticks {first}" if first else ""))  # fmt: skip
        self._send(P.stats(self.tx_seq, self.stats))
        self._end_session()
        self.state = HELLO


__all__ = ["ACTIVE", "Board", "FAULTED", "HELLO", "IDLE", "READY"]

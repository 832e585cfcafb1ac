"""The board side of the link, driven byte by byte with a fake clock: latency semantics,
watchdog, missed deadlines, config checks, and every board-side fault."""
import math

import numpy as np
import pytest

from hil import protocol as P
from hil.board import ACTIVE, FAULTED, HELLO, IDLE, READY, Board
from hil.framing import FrameDecoder, encode_frame
from servo.config import Config
from servo.scenarios import scenario_inputs
from servo.runtime.simdriver import SimDriver

CFG = Config().replace(run={"duration_s": 0.01, "sample_rate_hz": 20_000.0},
                       drive={"mode_hz": [3000.0], "mode_zeta": [0.01], "mode_gain": [-0.01]},
                       scenario={"disturbance_start": 0.0})  # fmt: skip
MS = 1_000_000  # ns


class Host:
    """The host's side of the bytes, by hand."""

    def __init__(self, board: Board):
        self.board, self.seq, self.dec = board, 0, FrameDecoder()

    def send(self, make, now=0):
        self.board.feed(encode_frame(make(self.seq)), now)
        self.seq += 1

    def recv(self):
        out = [P.parse(b) for b in self.dec.feed(bytes(self.board.out))]
        self.board.out.clear()
        return [m for _, _, m in out]

    def start(self, d=0, b=1, watchdog_ms=5, late=0, rate=None, now=0):
        self.send(lambda s: P.hello(s, 42), now)
        self.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, b, d, watchdog_ms * 1000, late, rate or self.board.rate,
                                                    P.DEFAULT_READY_TIMEOUT_MS, self.board.cfg.run.seed)), now)  # fmt: skip
        msgs = self.recv()
        assert [type(m) for m in msgs] == [P.Info, P.Ready], msgs
        self.send(P.start, now)
        return msgs

    def command(self, tick0, *u, now=0):
        self.send(lambda s: P.commands(s, tick0, u), now)


def samples(msgs):
    return [m for m in msgs if isinstance(m, P.Samples)]


@pytest.mark.parametrize("d,b", [(0, 1), (2, 1), (3, 2)])
def test_lockstep_board_applies_the_command_of_sample_k_at_tick_k_plus_d(d, b):
    board = Board(CFG)
    host = Host(board)
    info, ready = host.start(d=d, b=b)
    assert info.nonce == 42 and info.sample_rate_hz == 20_000.0 and info.caps & P.CAP_LOCKSTEP
    ref = SimDriver(CFG.replace(link={"command_latency_ticks": d, "batch": b}), scenario_inputs(CFG))
    ref.configure()
    ref.activate()
    assert (ready.x, ready.i) == (ref.read()[0], ref.applied_current)  # READY: tick 0 and the holding current
    rng = np.random.default_rng(3)
    got, want, pending = [], [], []
    for k in range(60):  # the host's loop, by hand: sample k in, command k out
        while len(got) <= 3 * k:
            frames = samples(host.recv())
            assert frames, f"the board sent no sample for tick {k}: deadlock"
            for f in frames:
                assert f.tick0 == len(got) // 3 and len(f.values) == 3 * b
                got += f.values
        x, v = ref.read()
        want += (x, v, ref.applied_current)
        u = 2e-3 + 1e-3 * rng.standard_normal()
        ref.write(u)  # the SimDriver applies it at k + d
        pending.append(u)
        if len(pending) == b:
            host.command(k - b + 1, *pending)
            pending = []
    assert len(got) >= 3 * 60 and len(got) <= 3 * (60 + d + b)  # the board runs ahead by up to d ticks
    assert np.array_equal(np.array(got[: 3 * 60]), np.array(want))  # bit for bit, not close
    assert board.stats["missed_deadlines"] == 0 and board.state == ACTIVE


def test_watchdog_drops_to_zero_current_when_commands_stop():
    board = Board(CFG)
    host = Host(board)
    host.start(watchdog_ms=5, now=0)
    host.command(0, 0.01, now=1 * MS)
    assert board.k == 1 and board.applied_current == 0.01
    board.check_watchdog(6 * MS)  # exactly the watchdog time since the last command: not yet
    assert board.state == ACTIVE
    board.check_watchdog(6 * MS + 1)
    assert board.state == FAULTED and board.applied_current == 0.0
    fault, stats = host.recv()[-2:]
    assert fault.code == P.FAULT_WATCHDOG and "no command for 5.0 ms" in fault.text
    assert stats.counters["watchdog_trips"] == 1 and stats.counters["faults"] == 1
    host.command(1, 0.5, now=7 * MS)  # commands after the fault are ignored
    assert board.applied_current == 0.0 and board.k == 1


def test_realtime_board_holds_late_commands_then_faults_on_missed_deadlines():
    board = Board(CFG, lockstep=False)
    host = Host(board)
    host.start(d=1, late=2)
    u_hold = board.applied_current
    board.tick(0)  # tick 0: nothing due yet (d = 1): the holding current
    host.command(0, 0.02)
    board.tick(0)  # tick 1: u_0 applied
    assert board.applied_current == 0.02 and board.stats["missed_deadlines"] == 0
    board.tick(0)  # tick 2: u_1 missing -> held
    board.tick(0)  # tick 3: u_2 missing -> held
    assert board.stats["missed_deadlines"] == 2 and board.state == ACTIVE and board.applied_current == 0.02
    host.command(1, 0.03)  # u_1 arrives after its tick
    assert board.stats["late_commands"] == 1
    frames = samples(host.recv())
    assert [f.status for f in frames] == [0, 0, P.STATUS_HELD, P.STATUS_HELD] and frames[-1].missed == 2
    assert frames[0].values[2] == u_hold
    board.tick(0)  # tick 4: u_3 missing, the third in a row > late_limit 2
    assert board.state == FAULTED and board.applied_current == 0.0
    fault = [m for m in host.recv() if isinstance(m, P.Fault)][0]
    assert fault.code == P.FAULT_DEADLINE and "host too slow" in fault.text


@pytest.mark.parametrize(
    "lockstep,change,needle",
    [
        (False, dict(d=1, b=2), "latency 1 ticks < batch 2"),
        (True, dict(d=0, b=2), "would deadlock"),
        (True, dict(rate=50_000.0), "the host expects 50000 Hz, the board samples at 20000 Hz"),
        (True, dict(b=40), "batch 40 outside 1..32"),
    ],
)
def test_config_outside_what_the_board_accepts_is_refused(lockstep, change, needle):
    board = Board(CFG, lockstep=lockstep)
    host = Host(board)
    host.send(lambda s: P.hello(s, 1))
    d, b, rate = change.get("d", 0), change.get("b", 1), change.get("rate", board.rate)
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, b, d, 1000, 0, rate)))
    fault = host.recv()[1]
    assert fault.code == P.FAULT_CONFIG and needle in fault.text
    assert board.state == FAULTED


def _running(d=2):
    board = Board(CFG)
    host = Host(board)
    host.start(d=d)
    host.first = samples(host.recv())[0]
    return board, host


@pytest.mark.parametrize(
    "inject,code,counter",
    [
        ("duplicate", P.FAULT_SEQUENCE, "seq_repeated"),
        ("skip", P.FAULT_SEQUENCE, "seq_dropped"),
        ("nan", P.FAULT_COMMAND, None),
        ("ahead", P.FAULT_COMMAND, None),
        ("corrupt", P.FAULT_CORRUPT, "crc_errors"),
        ("malformed", P.FAULT_PROTOCOL, "malformed"),
        ("wrong state", P.FAULT_PROTOCOL, None),
    ],
)
def test_every_board_side_fault_ends_in_the_safe_state(inject, code, counter):
    board, host = _running()
    host.command(0, 0.01)
    if inject == "duplicate":
        host.seq -= 1
        host.command(0, 0.01)
    elif inject == "skip":
        host.seq += 1
        host.command(1, 0.01)
    elif inject == "nan":
        host.command(1, math.nan)
    elif inject == "ahead":
        host.command(1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # commands for samples not sent yet
    elif inject == "corrupt":
        frame = bytearray(encode_frame(P.commands(host.seq, 1, (0.01,))))
        frame[5] ^= 0x10
        board.feed(bytes(frame), 0)
    elif inject == "malformed":
        host.send(lambda s: P.commands(s, 1, (0.01,))[:-1])
    elif inject == "wrong state":
        host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 1000, 0, board.rate)))
    assert board.state == FAULTED and board.applied_current == 0.0
    fault, stats = host.recv()[-2:]
    assert fault.code == code, fault
    if counter:
        assert stats.counters[counter] == 1
    assert stats.counters["faults"] == 1


def test_stop_answers_stats_and_a_new_config_starts_the_drive_afresh():
    board, host = _running(d=0)
    for k in range(5):
        host.command(k, 0.05)
    host.recv()
    host.send(P.stop)
    assert board.state == HELLO and board.applied_current == 0.0
    (stats,) = host.recv()
    assert stats.counters["ticks"] == 5 and stats.counters["rx_frames"] == 3 + 5 + 1
    seed = board.cfg.run.seed
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 1000, 0, board.rate, 2000, seed)))
    host.send(P.start)
    again = samples(host.recv())
    assert board.state == ACTIVE and again[0].values == host.first.values  # same initial state and noise
    host.send(P.stop)
    host.recv()
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 1000, 0, board.rate, 2000, seed + 1)))
    host.send(P.start)
    other = samples(host.recv())  # the CONFIG's seed, not the emulator's config's: other noise
    assert board.state == ACTIVE and other[0].values[1] != host.first.values[1]  # v: its noise is not quantised


def test_bytes_outside_a_session_are_ignored_and_a_hello_is_refused_while_a_session_holds_the_board():
    board = Board(CFG)
    board.feed(b"\x13\x37 line noise \x00" + encode_frame(P.commands(0, 0, (1.0,))), 0)
    assert board.state == IDLE and not board.out and board.decoder.errors == 1
    host = Host(board)
    host.start(watchdog_ms=5)
    host.command(0, 0.01, now=1 * MS)
    host.recv()
    assert board.state == ACTIVE and board.applied_current == 0.01
    other = Host(board)
    other.send(lambda s: P.hello(s, 9), now=2 * MS)  # a second host, while the first one runs
    assert board.state == ACTIVE and board.applied_current == 0.01 and board.refused_hellos == 1
    assert not board.out  # nothing sent: the running host's stream is not disturbed
    board.check_watchdog(7 * MS)  # the first host falls silent: its watchdog ends the session
    assert board.state == FAULTED and board.applied_current == 0.0
    host.recv()
    other.seq = 0
    other.send(lambda s: P.hello(s, 9), now=8 * MS)
    assert board.state == HELLO and board.applied_current == 0.0
    assert other.recv()[0].nonce == 9


def _ready(watchdog_ms=5, ready_timeout_ms=500):
    board = Board(CFG)
    host = Host(board)
    host.send(lambda s: P.hello(s, 1))
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, watchdog_ms * 1000, 0, board.rate, ready_timeout_ms)))
    assert board.state == READY and host.recv()[-1].i == board.applied_current
    return board, host


def test_a_ready_board_holds_its_drive_only_until_the_ready_timeout():
    board, host = _ready(watchdog_ms=5, ready_timeout_ms=500)
    u_hold = board.applied_current
    assert u_hold != 0.0  # READY holds the drive with the holding current (bumpless start)
    assert board.watchdog_due_ns() == 500 * MS
    board.check_watchdog(500 * MS)
    assert board.state == READY and board.applied_current == u_hold
    board.check_watchdog(500 * MS + 1)  # the host never started nor stopped: it is gone
    assert board.state == FAULTED and board.applied_current == 0.0 and board.watchdog_due_ns() is None
    fault, stats = host.recv()
    assert fault.code == P.FAULT_WATCHDOG and "after READY" in fault.text
    assert stats.counters["watchdog_trips"] == 1


def test_the_ready_timeout_is_the_configs_and_restarts_on_any_host_frame():
    """Issue 28: the ready timeout is a CONFIG value (it was the board's fixed 2 s, which
    a host's first kernel compile outlasted); neither the watchdog nor a board default
    lengthens it."""
    board, host = _ready(watchdog_ms=2000, ready_timeout_ms=500)
    assert board.watchdog_due_ns() == 500 * MS
    board, host = _ready(watchdog_ms=5, ready_timeout_ms=5000)
    board.check_watchdog(4999 * MS)
    assert board.state == READY  # a longer timeout than the old fixed 2 s, when the host asks for it
    board.check_watchdog(5000 * MS + 1)
    assert board.state == FAULTED and board.applied_current == 0.0
    board, host = _ready(watchdog_ms=5, ready_timeout_ms=500)
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 5000, 0, board.rate, 500)), now=400 * MS)
    assert board.state == READY and board.watchdog_due_ns() == 900 * MS  # reconfigured: counted from then


LIMITS = [  # (field changes, what the refusal names)
    ({"watchdog_us": P.MAX_WATCHDOG_US + 1}, "watchdog 60000001 us outside 1..60000000 us"),
    ({"watchdog_us": 2**32 - 1}, "watchdog 4294967295 us outside"),  # the red team's 71 minutes
    ({"watchdog_us": 0}, "watchdog 0 us outside"),
    ({"ready_timeout_ms": 0}, "ready timeout 0 ms outside 1..60000 ms"),
    ({"ready_timeout_ms": P.MAX_READY_TIMEOUT_MS + 1}, "ready timeout 60001 ms outside"),
    ({"ready_timeout_ms": 65535}, "ready timeout 65535 ms outside"),
    ({"late_limit": 101, "watchdog_us": 5000}, "late limit 101 ticks (5.05 ms) is longer than the watchdog (5 ms)"),
    ({"late_limit": 65535, "watchdog_us": 1000}, "late limit 65535 ticks"),
    ({"seed": 2**63}, "seed 9223372036854775808 > 9223372036854775807"),
    ({"seed": 2**64 - 1}, "seed 18446744073709551615 >"),
]


@pytest.mark.parametrize("change,needle", LIMITS, ids=[next(iter(c)) + str(i) for i, (c, _) in enumerate(LIMITS)])
def test_the_board_refuses_a_config_beyond_its_documented_limits(change, needle):
    """Issue 28: another host gets no cap from ``servo``'s config checks, so the board caps
    every CONFIG value itself: beyond a limit of docs/protocol.md it answers FAULT 6 and
    stays at zero current (it took a 71-minute watchdog and held 1 A for a silent host)."""
    board = Board(CFG, lockstep=False)
    host = Host(board)
    host.send(lambda s: P.hello(s, 1))
    msg = P.ConfigMsg(P.VERSION, 1, 1, 5000, 0, board.rate)._replace(**change)
    host.send(lambda s: P.config(s, msg))
    info, fault, stats = host.recv()
    assert fault.code == P.FAULT_CONFIG and needle in fault.text, fault.text
    assert board.state == FAULTED and board.applied_current == 0.0 and board.watchdog_due_ns() is None


def test_the_limits_themselves_are_accepted():
    board = Board(CFG, lockstep=False)
    host = Host(board)
    host.send(lambda s: P.hello(s, 1))
    rate = int(board.rate)
    msg = P.ConfigMsg(P.VERSION, 1, 1, P.MAX_WATCHDOG_US, 65535, board.rate, P.MAX_READY_TIMEOUT_MS)
    host.send(lambda s: P.config(s, msg))
    assert board.state == READY and board.watchdog_due_ns() == P.MAX_READY_TIMEOUT_MS * MS
    host.send(P.stop)
    host.send(lambda s: P.config(s, msg._replace(watchdog_us=1000, late_limit=rate // 1000)))  # exactly the watchdog
    assert board.state == READY


@pytest.mark.parametrize("how", ["stop", "disconnect"])
def test_stop_or_a_lost_host_in_ready_is_the_safe_state(how):
    board, host = _ready()
    assert board.applied_current != 0.0
    if how == "stop":
        host.send(P.stop)
        assert board.state == HELLO and isinstance(host.recv()[-1], P.Stats)
    else:
        board.disconnect(0)
        assert board.state == IDLE and board.stats["faults"] == 1
    assert board.applied_current == 0.0 and board.watchdog_due_ns() is None


def test_safe_state_in_every_board_state():
    """Zero current in IDLE, HELLO and FAULTED; READY and ACTIVE have a deadline."""
    board = Board(CFG)
    host = Host(board)
    assert board.state == IDLE and board.applied_current == 0.0 and board.watchdog_due_ns() is None
    host.send(lambda s: P.hello(s, 1))
    assert board.state == HELLO and board.applied_current == 0.0 and board.watchdog_due_ns() is None
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 1000, 0, board.rate)))
    assert board.state == READY and board.watchdog_due_ns() is not None
    host.send(P.start)
    assert board.state == ACTIVE and board.watchdog_due_ns() is not None
    host.send(P.stop)
    assert board.state == HELLO and board.applied_current == 0.0 and board.watchdog_due_ns() is None


def test_a_closed_connection_is_the_safe_state():
    board, host = _running()
    board.disconnect(0)
    assert board.state == IDLE and board.applied_current == 0.0 and board.sessions_ended == 1
    assert board.stats["faults"] == 1


def test_ready_state_needs_start_before_commands():
    board = Board(CFG)
    host = Host(board)
    host.send(lambda s: P.hello(s, 1))
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 1000, 0, board.rate)))
    assert board.state == READY
    host.command(0, 0.1)
    assert board.state == FAULTED and host.recv()[-2].code == P.FAULT_PROTOCOL


def test_a_fixed_seed_overrides_the_hosts():
    """``servo emulate --seed N``: every run draws seed N's noise, whatever seed the
    host's CONFIG carries; without it, the CONFIG's seed decides."""
    first = {}
    for fixed, seed in ((5, 1), (5, 2), (None, 5), (None, 2)):
        board = Board(CFG, seed=fixed)
        host = Host(board)
        host.send(lambda s: P.hello(s, 42))
        host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 5000, 0, board.rate, 2000, seed)))
        host.recv()
        host.send(P.start)
        first[fixed, seed] = samples(host.recv())[0].values
    assert first[5, 1] == first[5, 2] == first[None, 5] != first[None, 2]

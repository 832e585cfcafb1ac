"""Benchmarks of the serial link (issue 4): the host's per-frame cost, and the round trip
over a pseudo-terminal through the device emulator.

* ``test_host_cost_per_frame``: ``read`` + ``write`` of every tick of one frame on the
  host (decode SAMPLES with sequence/tick checks, encode COMMANDS), against a replay
  port (no system calls), for b = 1 and b = 8.  Reference measured in the same run: the
  simulated drive's ``read`` + ``write`` per tick (plant step included).
* ``test_round_trip_over_a_pty``: one lockstep tick through ``servo emulate`` in its own
  process over a pty (host read + write, board step, both directions through the
  kernel).  Reference measured in the same run: the bare pty echo round trip of a
  64-byte message between two Python processes.  Both ends of both round trips are
  pinned to one core.

Every asserted ratio is the median of 101 adjacent pairs of short blocks of equal
duration (:func:`bench.timing.paired_blocks`), so it holds on a loaded machine.

The real-time figure (highest sample rate with zero missed deadlines) is measured by
``bench/link_rate.py``, not here: it takes minutes and a quiet machine.
"""
from __future__ import annotations

import os
import re
import select
import subprocess
import sys
from contextlib import contextmanager

import pytest

from hil import protocol as P
from hil.board import Board
from hil.emulator import start_in_thread
from hil.framing import encode_frame
from hil.serialdriver import SerialDriver
from servo.config import Config, to_toml
from servo.runtime.simdriver import SimDriver

from bench.timing import paired_blocks

FRAMES = 2000  # frames per benchmark round
PAIRS = 101
"""Adjacent (link, reference) pairs timed for each asserted ratio."""


class ReplayPort:
    """A port that hands out prepared frames and swallows what is written: the host's
    cost without system calls."""

    def __init__(self, data: list[bytes]):
        self.data, self.i, self.written = data, 0, 0

    def read(self, n):
        if self.i == len(self.data):
            return b""
        self.i += 1
        return self.data[self.i - 1]

    def write(self, data):
        self.written += len(data)

    def close(self):
        pass


def sim_ticks(cfg):
    """Reference: a function running ``n`` SimDriver read + write ticks (plant step included)."""
    s = SimDriver(cfg)
    s.configure()
    s.activate()
    read, write = s.read, s.write

    def ticks(n: int) -> None:
        for _ in range(n):
            read()
            write(0.002)

    return ticks


@pytest.mark.parametrize("b", [1, 8])
def test_host_cost_per_frame(benchmark, b):
    """The host's link cost per frame against SimDriver ticks, in adjacent pairs; the
    median of the per-pair ratios is asserted."""
    cfg = Config().replace(run={"duration_s": 60.0}, link={"command_latency_ticks": b, "batch": b})
    board = Board(cfg)
    with start_in_thread(board) as url:
        drv = SerialDriver(cfg, url)
        drv.configure()
        drv.activate()
    n = FRAMES * 30
    seq0 = drv._rx_seq
    vals = [1e-6, -2e-5, 0.002] * b
    frames = [encode_frame(P.samples((seq0 + m) % P.SEQ_MOD, m * b, 0, 0, vals)) for m in range(n)]
    drv._port = ReplayPort(frames)
    read, write = drv.read, drv.write

    def frame():
        for _ in range(b):
            read()
            write(0.002)

    def frames(n: int) -> None:
        for _ in range(n):
            read()
            write(0.002)

    sim = sim_ticks(cfg)
    benchmark.pedantic(frame, rounds=5, iterations=FRAMES, warmup_rounds=1)  # the figure pytest-benchmark shows
    pairs = paired_blocks(frames, sim, pairs=PAIRS, quantum_a=b)
    per_tick_us, ref, ratio = pairs.a_ns / 1e3, pairs.b_ns / 1e3, pairs.ratio  # per tick of the link / per simulated tick
    benchmark.extra_info.update(per_frame_us=per_tick_us * b, per_tick_us=per_tick_us, sim_tick_us=ref,
                                ratio_to_sim_tick=ratio)  # fmt: skip
    print(f"\nb={b}: host link cost {per_tick_us * b:.2f} us/frame, {per_tick_us:.2f} us/tick; "
          f"SimDriver tick {ref:.2f} us; median ratio of {PAIRS} adjacent pairs {ratio:.2f}")
    # budget (measured 1.5 and 0.5 on the 2-core development machine): the link costs the
    # host at most 2.5 simulated-drive ticks per tick unbatched, less than one batched
    assert ratio < (2.5 if b == 1 else 1.0)
    port = drv._port
    assert port.i >= PAIRS and port.written == len(encode_frame(P.commands(0, 0, [0.0] * b))) * port.i  # all answered


@contextmanager
def one_core():
    """This process pinned to one core (restored after); yields the core.  The round-trip
    benchmark pins its peers there too: where the two ends of a round trip run (one core,
    or two) sets its cost more than anything else, so both figures of a pair must be
    taken with the same placement."""
    old = os.sched_getaffinity(0)
    core = min(old)
    os.sched_setaffinity(0, {core})
    try:
        yield core
    finally:
        os.sched_setaffinity(0, old)


@contextmanager
def pty_echo(core: int):
    """Reference: a Python echo process on a raw pty, pinned to ``core``.  Yields
    ``round_trips(n)``, which sends a 64-byte message and waits for it back, ``n`` times."""
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    echo = subprocess.Popen([sys.executable, "-c", "import os\nwhile True:\n d=os.read(0,4096)\n if not d: break\n os.write(1,d)"],
                            stdin=slave, stdout=slave, preexec_fn=lambda: os.sched_setaffinity(0, {core}))  # fmt: skip
    msg = b"x" * 63 + b"\0"

    def round_trips(n: int) -> None:
        for _ in range(n):
            os.write(master, msg)
            got = 0
            while got < 64:
                select.select([master], [], [])
                got += len(os.read(master, 4096))

    try:
        round_trips(100)
        yield round_trips
    finally:
        echo.kill()
        echo.wait()
        os.close(master)
        os.close(slave)


@contextmanager
def emulator_process(cfg, tmp_path, core: int):
    f = tmp_path / "cfg.toml"
    f.write_text(to_toml(cfg))
    proc = subprocess.Popen([sys.executable, "-m", "servo", "emulate", "--pty", "--config", str(f), "--cpu", str(core)],
                            stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 60)
        m = re.search(r"listening on (\S+)", proc.stdout.readline() if ready else "")
        assert m, "emulator did not start"
        yield m.group(1)
    finally:
        proc.terminate()
        proc.wait(10)


@pytest.mark.parametrize("d,b", [(0, 1), (8, 8)])
def test_round_trip_over_a_pty(benchmark, d, b, tmp_path):
    """The link's lockstep tick against the bare pty echo, in adjacent pairs (alternating
    which goes first); the median of the per-pair ratios is asserted.  A neighbour that
    slows the machine slows both blocks of a pair, where the two figures taken apart moved
    independently (one busy core moved the echo alone 22 -> 50 us)."""
    cfg = Config().replace(run={"duration_s": 10.0}, link={"command_latency_ticks": d, "batch": b, "watchdog_s": 5.0})
    with one_core() as core, emulator_process(cfg, tmp_path, core) as url, pty_echo(core) as echo:
        drv = SerialDriver(cfg, url)
        drv.configure()
        drv.activate()
        read, write = drv.read, drv.write

        def ticks(n: int) -> None:
            for _ in range(n):
                read()
                write(0.002)

        try:
            benchmark.pedantic(ticks, args=(16 * b,), rounds=5, iterations=1, warmup_rounds=1)  # pytest-benchmark's figure
            pairs = paired_blocks(ticks, echo, pairs=PAIRS, quantum_a=b)
        finally:
            drv.close()
    per_tick_us, echo_us, ratio = pairs.a_ns / 1e3, pairs.b_ns / 1e3, pairs.ratio  # per tick / per echo round trip
    benchmark.extra_info.update(per_tick_us=per_tick_us, pty_echo_us=echo_us, ratio_to_pty_echo=ratio)
    print(f"\nd={d} b={b}: lockstep tick through the emulator over a pty {per_tick_us:.1f} us; "
          f"bare pty echo round trip {echo_us:.1f} us; median ratio of {PAIRS} adjacent pairs {ratio:.2f}")
    assert drv.board_stats is not None and drv.board_stats["faults"] == 0
    # budget: the median pair ratio measured 0.69-1.63 idle, 1.57-3.10 with one busy core
    # and 1.47-4.90 with two (d = 0), 0.10-0.73 batched, 1.41-1.67 batched with two busy
    # beside seven other sessions at load 19-27 (bench/README.md).  It is set by
    # the OS (wake-up of an idle core; a spinner sharing the pinned core preempts the side
    # with more Python work), so the bounds only catch a gross regression, 1.5x above the
    # worst loaded figure; the host's own cost is guarded precisely by
    # test_host_cost_per_frame (no system calls: 1.33-1.41 at every load)
    assert ratio < (7.5 if b == 1 else 2.5)

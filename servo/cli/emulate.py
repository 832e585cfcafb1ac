"""``servo emulate``: the device emulator, a separate process that plays the DSP/VCM board."""
from __future__ import annotations

import argparse
import sys

from servo.cli.common import add_config_options, config_from_args
from servo.errors import ServoError


def register(sub) -> None:
    p = sub.add_parser(
        "emulate",
        help="play the DSP/VCM board: the simulated drive behind the serial protocol",
        description="Run the simulated drive of the config behind the board side of the serial protocol "
        "(docs/protocol.md), on a pseudo-terminal (prints its path) or a TCP port on 127.0.0.1. In lockstep "
        "(default) the board advances when commands arrive, so a run through it is bit-identical to the "
        "simulator; with --realtime it is the clock master at run.sample_rate_hz. Give it the config the host "
        "runs with (the disturbance comes from it; the noise seed from each run's CONFIG, the host's run.seed). "
        "Stop with Ctrl-C or SIGTERM.",
    )
    add_config_options(p)
    p.add_argument("--seed", type=int, help="a fixed sensor-noise seed for every run (default: each run's, sent by "
                   "the host in CONFIG)")  # fmt: skip
    p.add_argument("--duration", type=float, metavar="S", help="length of the scenario's disturbance array "
                   "(default: run.duration_s; give the host's)")  # fmt: skip
    where = p.add_mutually_exclusive_group()
    where.add_argument("--pty", action="store_true", help="listen on a new pseudo-terminal (default)")
    where.add_argument("--tcp", type=int, metavar="PORT", help="listen on 127.0.0.1:PORT (0: any free port)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", action="store_true", help="advance when the command arrives (default)")
    mode.add_argument("--realtime", action="store_true", help="be the clock master at the sample rate")
    p.add_argument("--sessions", type=int, metavar="N", help="exit after N host sessions (default: run until stopped)")
    p.add_argument("--name", default="servo emulator", help="board name reported in INFO")
    p.add_argument("--cpu", type=int, metavar="N", help="real time: pin the emulator to CPU N")
    p.add_argument("--fifo", type=int, metavar="PRIO", help="real time: SCHED_FIFO at this priority, if permitted")
    p.add_argument("--lock-memory", action="store_true", help="real time: mlockall, if permitted")
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from contextlib import nullcontext

    from hil.board import Board
    from hil.emulator import open_transport, serve
    from servo.runtime.pacing import realtime_section

    if args.sessions is not None and args.sessions < 1:
        raise ServoError("emulate: --sessions must be >= 1")
    cfg = config_from_args(args, run={"seed": args.seed, "duration_s": args.duration})  # --seed checked here

    def say(line: str) -> None:
        print(f"servo emulate: {line}", flush=True)

    board = Board(cfg, lockstep=not args.realtime, name=args.name, log=say, seed=args.seed)
    try:
        transport = open_transport("tcp" if args.tcp is not None else "pty", args.tcp or 0)
    except OSError as exc:
        raise ServoError(f"emulate: cannot listen: {exc}") from None
    mode = "real time" if args.realtime else "lockstep"
    ctx = (realtime_section(args.cpu, args.fifo, args.lock_memory) if args.realtime else nullcontext())
    try:  # it says "stop with Ctrl-C": servo.cli.main takes SIGINT back if it was ignored
        with ctx as grant:
            seed = "the host's seed" if args.seed is None else f"seed {args.seed}"
            say(f"listening on {transport.url} ({mode}, {cfg.run.sample_rate_hz:g} Hz, {seed}); "
                "stop with Ctrl-C")  # fmt: skip
            for note in getattr(grant, "notes", []):
                say(note)
            serve(board, transport, realtime=args.realtime, sessions=args.sessions)
    except KeyboardInterrupt:
        open_ = board.session - board.sessions_ended  # a session stopped by this interrupt
        during = f", session {board.session} interrupted in state {board.state}" if open_ else ""
        say(f"stopped after {board.session} session(s){during}; drive at zero current")
        return 0
    finally:
        transport.close()
        sys.stdout.flush()
    say(f"done after {board.sessions_ended} session(s)")
    return 0

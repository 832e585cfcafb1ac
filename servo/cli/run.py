"""``servo run``: the closed loop (PI holding loop + compensator) on the simulated drive."""
from __future__ import annotations

import argparse
from pathlib import Path

from servo.cli import UsageError
from servo.cli.common import add_config_options, config_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run the closed loop against the simulated drive (or a board: --port URL)",
        description="Run the closed loop (PI holding loop plus the paper's compensator) against the simulated "
        "drive: hold, reference steps, a sinusoidal disturbance. Prints a summary; writes logs, summary.json "
        "and PNG plots into the output folder.",
    )
    add_config_options(p)
    p.add_argument("--duration", type=float, metavar="S", help="simulated seconds (default: run.duration_s)")
    p.add_argument("--seed", type=int, help="sensor-noise seed (default: run.seed)")
    p.add_argument("--out", metavar="DIR", help="output folder (default: servo-out/run-<time>)")
    p.add_argument("--compensation", choices=("on", "off", "compare"), default="compare",
                   help="run with the compensator, without, or both and compare (default)")  # fmt: skip
    p.add_argument("--fast", action=argparse.BooleanOptionalAction, default=None,
                   help="all-compiled fast path instead of tick by tick (default: run.fast_path)")  # fmt: skip
    p.add_argument("--port", metavar="URL", help="run against a DSP/VCM board (or `servo emulate`) over this "
                   "pyserial URL: a device or pseudo-terminal path, socket://HOST:PORT, ... (the [link] section "
                   "sets latency, batching, timeouts)")  # fmt: skip
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.runjob import default_out_dir, format_summary, run_job

    cfg = config_from_args(args, run={"duration_s": args.duration, "seed": args.seed})
    out = Path(args.out) if args.out else default_out_dir()
    if args.port is None:
        summary = run_job(cfg, out, compensation=args.compensation, fast=args.fast)
    else:
        summary = _run_on_port(cfg, out, args)
    print(format_summary(summary, out))
    return 0


def _run_on_port(cfg, out: Path, args: argparse.Namespace) -> dict:
    """The same job against the serial link: a fresh session (driver) per run.  The first
    driver is configured (handshake, version and rate checks) before anything is written,
    so a bad URL or an absent board leaves no output folder."""
    from hil.serialdriver import SerialDriver
    from servo.pacing import realtime_section
    from servo.runjob import run_job

    if args.fast or (args.fast is None and cfg.run.fast_path):
        raise UsageError("servo run: --port runs tick by tick through the link; drop --fast (run.fast_path)")
    first = SerialDriver(cfg, args.port)
    first.configure()
    pending = [first]

    def make_driver(cfg, inputs):
        return pending.pop() if pending else SerialDriver(cfg, args.port)

    try:
        with realtime_section():  # no garbage-collector pauses while the board waits for commands
            return run_job(cfg, out, compensation=args.compensation, fast=False, make_driver=make_driver,
                           where=f"{first.info.name} (d = {cfg.link.command_latency_ticks}, "
                           f"batch = {cfg.link.batch})")  # fmt: skip
    finally:
        first.close()

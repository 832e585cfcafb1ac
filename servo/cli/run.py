"""``servo run``: the closed loop (PI holding loop + compensator) on the simulated drive."""
from __future__ import annotations

import argparse
from pathlib import Path

from servo.cli.common import add_config_options, config_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run the closed loop against the simulated drive",
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
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.runjob import default_out_dir, format_summary, run_job

    cfg = config_from_args(args, run={"duration_s": args.duration, "seed": args.seed})
    out = Path(args.out) if args.out else default_out_dir()
    summary = run_job(cfg, out, compensation=args.compensation, fast=args.fast)
    print(format_summary(summary, out))
    return 0

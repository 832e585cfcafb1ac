"""``servo compensate``: a compensator section from a diagnosis or an identification."""
from __future__ import annotations

import argparse
from pathlib import Path

from servo.cli.common import add_config_options, config_from_args, recording_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "compensate",
        help="write the compensator that cancels what a diagnosis or an identification found",
        description="Reads a report.json of servo diagnose (its final model), a summary.json of servo identify, "
        "or a servo config (its [drive]) and writes the [compensator] section that cancels each term a static "
        "term can cancel, with its authority bounded so that a wrong model cannot destabilise the loop "
        "(docs/compensate.md). The base config (--config/--set) gives the controller, the current limit and "
        "the stroke.",
    )
    p.add_argument("source", metavar="SOURCE", help="report.json, summary.json or a config .toml")
    add_config_options(p)
    p.add_argument("--out", metavar="FILE", default="compensator.toml", help="TOML written (default compensator.toml)")
    p.add_argument("--full", action="store_true", help="write the whole base config with the section, not the section alone")
    p.add_argument("--paper", action="store_true", help="only what eq. 9 can hold (the paper's compensator of this model)")
    p.add_argument("--force-constant", type=float, metavar="N_PER_A", help="convert a model in N to A (required for one)")
    p.add_argument("--authority", type=float, metavar="A", help="bound |u_c| at this many A instead of the computed bound")
    p.add_argument("--recording", metavar="REC", help="also print the force residual each compensator leaves on this "
                   "recording (its held-out part), the paper's and the augmented one, and what each term removes")
    p.add_argument("--columns", metavar="ROLE=NAME,...", help="the recording's columns, as for servo diagnose")
    p.add_argument("--scale", metavar="ROLE=FACTOR,...", help="the recording's scaling, as for servo diagnose")
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.compensate.job import compensate, format_residual, format_summary, on_recording, write
    from servo.errors import ConfigError

    base = config_from_args(args)
    if args.authority is not None and not args.authority > 0:
        raise ConfigError("--authority must be a positive number of A")
    try:
        p = compensate(args.source, base, args.paper, args.force_constant, args.authority)
    except ValueError as exc:
        raise ConfigError(f"compensate: {exc}") from None
    residual = None
    if args.recording:
        rec = recording_from_args(args)
        try:
            residual = on_recording(args.source, base, rec, args.force_constant, args.authority)
        except ValueError as exc:
            raise ConfigError(f"compensate: {exc}") from None
    out = Path(args.out)
    write(p, base, out, args.full)
    print(format_summary(p))
    if residual is not None:
        print(format_residual(residual))
    print(f"  wrote {out}")
    return 0

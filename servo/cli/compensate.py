"""``servo compensate``: a compensator section from a diagnosis or an identification."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from servo.cli.common import add_config_options, add_quiet_option, config_from_args, progress_from_args, recording_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "compensate",
        help="write the compensator that cancels what a diagnosis or an identification found",
        description="Reads a report.json of servo diagnose (its final model), a summary.json of servo identify, "
        "or a servo config (its [drive]) and writes the [compensator] section that cancels each term a static "
        "term can cancel and the source found distinguishable from zero, with its authority bounded so that a "
        "wrong model cannot destabilise the loop; checks it on the model in closed loop (the steps and the "
        "disturbance of servo run, and Fig. 8) against eq. 9's compensator and against none, and refuses one "
        "that tracks worse than none (docs/compensate.md). The base config (--config/--set) gives the "
        "controller, the current limit and the stroke. Writes compensator.toml and summary.json into --out.",
    )
    p.add_argument("source", metavar="SOURCE", help="report.json, summary.json or a config .toml")
    add_config_options(p)
    p.add_argument("--out", metavar="DIR", help="output folder, new or empty (default servo-out/compensate-<time>): "
                   "compensator.toml and summary.json")  # fmt: skip
    p.add_argument("--full", action="store_true", help="compensator.toml holds the whole base config with the section")
    p.add_argument("--paper", action="store_true", help="only what eq. 9 can hold (the paper's compensator of this model)")
    p.add_argument("--force-constant", type=float, metavar="N_PER_A",
                   help="convert a model in N to A (without it, the section is in the model's unit)")
    p.add_argument("--authority", type=float, metavar="F", help="bound |u_c| at this force (the section's unit) "
                   "instead of the computed bound")  # fmt: skip
    p.add_argument("--no-check", action="store_true", help="skip the check on the model (propose the augmented "
                   "compensator, or eq. 9's with --paper, unchecked)")  # fmt: skip
    p.add_argument("--allow-worse", action="store_true", help="write the compensator even when, on the model, it "
                   "tracks the steps worse than no compensator (the warning stays)")  # fmt: skip
    p.add_argument("--recording", metavar="REC", help="also print the force residual each compensator leaves on this "
                   "recording (its held-out part), the paper's and the augmented one, and what each term removes")
    p.add_argument("--columns", metavar="ROLE=NAME,...", help="the recording's columns, as for servo diagnose")
    p.add_argument("--scale", metavar="ROLE=FACTOR,...", help="the recording's scaling, as for servo diagnose")
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.compensate.job import format_residual, format_summary, on_recording, recommend, write
    from servo.compensate.model import CompensateError
    from servo.errors import ConfigError
    from servo.io.outdir import check_output, staged
    from servo.io.progress import reporting

    base = config_from_args(args)
    if args.authority is not None and not args.authority > 0:
        raise ConfigError("--authority must be a positive number")
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("compensate-%Y%m%d-%H%M%S")
    check_output(out)  # before the work: an existing file or folder (an input) is never replaced
    with reporting(progress_from_args(args, "servo compensate")):
        try:
            r = recommend(args.source, base, args.paper, args.force_constant, args.authority, not args.no_check)
        except ValueError as exc:
            raise ConfigError(f"compensate: {exc}") from None
        residual = None
        if args.recording:
            rec = recording_from_args(args)
            try:
                residual = on_recording(args.source, base, rec, args.force_constant, args.authority)
            except ValueError as exc:
                raise ConfigError(f"compensate: {exc}") from None
    text = format_summary(r)
    refusal = r.refusal()
    if refusal and not args.allow_worse:
        print(text)
        raise CompensateError(f"compensate: {refusal}; nothing written (--allow-worse writes it anyway)")
    from servo.io.provenance import provenance

    inputs = [args.source, args.config, args.recording]
    with staged(out) as tmp:  # the folder appears complete, or not at all
        files = write(r, base, tmp, args.full, {"provenance": provenance(base, inputs, args.argv)}, residual)
    print(text)
    if residual is not None:
        print(format_residual(residual, r.proposal.unit, r.proposal.position_unit))
    print(f"  wrote {out}/: " + ", ".join(files))
    return 0

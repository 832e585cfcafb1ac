"""``servo diagnose``: find the physics a model left out, model it, prove the fit improves."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from servo.cli.common import (add_position_unit_option, add_quiet_option, add_recording_options, progress_from_args,
                              recording_from_args)
from servo.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="find the physics a model leaves out of a recording, model it, prove the fit improves",
        description="Hold a model (a term set of eq. 3 fitted on the training part, or a model file) against a "
        "recording; locate where the residual is structured (time, state, frequency); name the missing physics "
        "from a vocabulary of candidate terms (blocked cross-validation, family-wise false-alarm level); fit it "
        "and prove the improvement on held-out data.  Writes report.json, report.html, final_model.toml and PNGs into --out.",
    )
    add_recording_options(p)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--baseline", metavar="TERMS", help="terms of eq. 3 fitted on the training part (default J,B,Fc,K,h0)")
    g.add_argument("--model", metavar="FILE", help="a fixed model: servo config TOML, identify summary.json or diagnose report.json")
    p.add_argument("--test-fraction", type=float, default=0.25, help="fraction of the recording held out at the end (default 0.25)")
    p.add_argument("--blocks", type=int, default=10, help="cross-validation blocks (default 10)")
    p.add_argument("--alpha", type=float, default=0.05, help="family-wise false-alarm level (default 0.05)")
    p.add_argument("--horizon", type=float, metavar="S", help="simulated-output horizon, s (default 10 row spacings)")
    p.add_argument("--cutoff-hz", type=float, help="Butterworth cutoff on position (default fs/decimation)")
    add_decimate_option(p)
    p.add_argument("--force-unit", help="unit of the input column for the report (default: the unit the file "
                   "declares, u [N], else A; N for EMPS)")  # fmt: skip
    add_position_unit_option(p)
    p.add_argument("--no-plots", action="store_true", help="write report.json, report.html and final_model.toml only")
    p.add_argument("--out", metavar="DIR", help="output folder (default servo-out/diagnose-<time>)")
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.diagnose.report import format_summary
    from servo.io.progress import reporting, stage

    with reporting(progress_from_args(args, "servo diagnose")):  # closed (its line cleared) before the summary
        report, out = _diagnose(args, stage)
    print(format_summary(report, out))
    return 0


def add_decimate_option(p: argparse.ArgumentParser) -> None:
    """``--decimate reversals|power|Q`` (default reversals): ``servo diagnose``'s, and
    ``servo fleet diagnose``'s."""
    p.add_argument("--decimate", metavar="reversals|power|Q", default="reversals",
                   help="parallel decimation factor Q, or the rule that chooses it from the recording: reversals "
                   "(default: the largest of 10, 8, 6, 5, 4, 3 whose rows the reversals leave usable) or power (as "
                   "reversals, among those whose band covers where the position stands 20 dB over its noise)")


def parse_decimate(value: str) -> tuple[str, int | None]:
    """``--decimate``: a rule of :data:`servo.diagnose.band.RULES` (``(rule, None)``) or a
    factor ``Q >= 1`` (``(default rule, Q)``)."""
    from servo.diagnose.band import RULES

    v = str(value).strip().lower()
    if v in RULES:
        return v, None
    try:
        q = int(v)
    except ValueError:
        q = 0
    if q < 1:
        raise ConfigError(f"--decimate {value!r}: expected {', '.join(RULES)} or a decimation factor >= 1")
    return RULES[0], q


def _diagnose(args: argparse.Namespace, stage) -> tuple[dict, Path]:
    from servo.io.outdir import staged
    from servo.diagnose.job import Options, diagnose
    from servo.diagnose.folder import write_outputs
    from servo.identify.regressors import RobustSettings

    if not 0.0 < args.alpha < 0.5:
        raise ConfigError(f"--alpha {args.alpha!r}: expected a level between 0 and 0.5")
    if args.horizon is not None and not args.horizon > 0:
        raise ConfigError(f"--horizon {args.horizon!r}: expected a positive number of seconds")
    from servo.io.allocator import LARGE_SAMPLES, keep_freed_memory

    stage("loading the recording")
    rec = recording_from_args(args)
    if rec.n >= LARGE_SAMPLES:  # large arrays reused, not faulted in afresh: 3/4 of the system time at 3e6 samples
        keep_freed_memory()
    rule, q = parse_decimate(args.decimate)
    settings = None if q is None else RobustSettings(cutoff_hz=args.cutoff_hz, decimate=q)
    opt = Options(baseline=args.baseline, model=args.model, test_fraction=args.test_fraction, blocks=args.blocks,
                  alpha=args.alpha, horizon_s=args.horizon, force_unit=args.force_unit, settings=settings,
                  position_unit=args.position_unit,
                  cutoff_hz=args.cutoff_hz, band=rule)  # fmt: skip
    D = diagnose(rec, opt)  # everything computed before any file is written
    stage("plots and the report")
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("diagnose-%Y%m%d-%H%M%S")
    from servo.io.provenance import provenance

    prov = provenance(None, [args.recording] + ([args.model] if args.model else []), args.argv)
    with staged(out) as tmp:  # the folder appears complete, or not at all
        report = write_outputs(D, tmp, prov, plots=not args.no_plots)
    return report, out

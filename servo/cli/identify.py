"""``servo identify``: least squares of eq. (4-5) on a recording, or on the simulated
drive's square-wave experiment (paper Fig. 5)."""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from servo.cli.common import (
    add_config_options, add_position_unit_option, add_quiet_option, add_recording_options, config_from_args,
    progress_from_args, recording_from_args,
)
from servo.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "identify",
        help="least-squares friction identification (eq. 4-5) from a recording",
        description="Estimate [J, B, Fc, K, h0] of J*x'' + B*x' + Fc*sgn(x') + K*x + h0 = u (paper eq. 3-5) from a "
        "recording (CSV/NPZ with t,u,x[,v] columns, or MATLAB .mat with --columns/--scale), with standard "
        "deviations, condition number and relative error; or, with --simulate, from the simulated drive's "
        "square-wave experiment. Writes summary.json, CSVs and PNGs (estimated vs measured acceleration, force fit).",
    )
    add_recording_options(p, optional=True)
    p.add_argument("--path", choices=("robust", "paper", "both"), default=None,
                   help="derivatives: robust (Butterworth + central differences + parallel decimation), paper "
                   "(measured velocity, backward-difference acceleration), or both (default: both when the "
                   "recording has v, else robust)")  # fmt: skip
    p.add_argument("--terms", metavar="T,...", help="terms to identify (default J,B,Fc,K,h0)")
    p.add_argument("--off", metavar="T,...", help="terms to switch off, e.g. K for a linear axis")
    p.add_argument("--cutoff-hz", type=float, help="robust path: Butterworth cutoff (default fs/10)")
    p.add_argument("--butter-order", type=int, default=4, help="robust path: Butterworth order (default 4)")
    p.add_argument("--decimate", type=int, default=10, help="robust path: parallel decimation factor (default 10; 1 = none)")
    p.add_argument("--trim", metavar="START,END", default="49,49",
                   help="robust path: samples dropped at each end after differentiation (default 49,49)")
    p.add_argument("--emps-reference", action="store_true",
                   help="robust path with the EMPS reference script's settings (drops the first 49 samples only)")
    p.add_argument("--force-lag", type=float, metavar="S", default=None,
                   help="seconds by which the recorded force acts late (input delay; with --path robust add half a "
                   "sample for a zero-order-held command). Default 0; with --simulate, the drive's input delay "
                   "(+ half a sample on the robust path)")  # fmt: skip
    p.add_argument("--force-unit", help="unit of the force column, for the report (default: the unit the file "
                   "declares, u [N], else A; N for EMPS)")  # fmt: skip
    add_position_unit_option(p)
    p.add_argument("--simulate", action="store_true", help="run the square-wave experiment on the simulated drive instead")
    p.add_argument("--amplitude", type=float, default=0.02, help="--simulate: square-wave amplitude, A (default 0.02)")
    p.add_argument("--hz", type=float, default=25.0, help="--simulate: square-wave frequency (default 25)")
    p.add_argument("--duration", type=float, default=1.0, help="--simulate: seconds (default 1)")
    p.add_argument("--holding-hz", type=float, default=5.0, help="--simulate: holding loop bandwidth (default 5)")
    add_config_options(p)
    p.add_argument("--out", metavar="DIR", help="output folder (default servo-out/identify-<time>)")
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def _trim(text: str) -> tuple[int, int]:
    try:
        a, b = (int(s) for s in text.split(","))
    except ValueError:
        raise ConfigError(f"--trim {text!r}: expected START,END sample counts, e.g. 49,49") from None
    return a, b


def handle(args: argparse.Namespace) -> int:
    from servo.io.progress import reporting

    with reporting(progress_from_args(args, "servo identify")):  # --quiet: no progress or compile lines
        return _handle(args)


def _handle(args: argparse.Namespace) -> int:
    from servo.io.outdir import staged
    from servo.identify.regressors import RobustSettings, parse_terms
    from servo.identify.job import format_summary, run_identify
    from servo.io.atomic import write_json
    from servo.io.recording import save_recording_csv

    terms = parse_terms(args.terms, args.off)
    start, end = _trim(args.trim)
    if args.emps_reference:
        settings = RobustSettings.emps_reference()
    else:
        settings = RobustSettings(butter_order=args.butter_order, cutoff_hz=args.cutoff_hz, decimate=args.decimate,
                                  trim_start=start, trim_end=end)  # fmt: skip
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("identify-%Y%m%d-%H%M%S")
    reference = None
    lag = 0.0 if args.force_lag is None else args.force_lag
    if lag < 0:
        raise ConfigError("--force-lag must be >= 0")
    if args.simulate:
        if args.recording:
            raise ConfigError("give a recording or --simulate, not both")
        from servo.experiments.square_wave import SquareWave, nominal, representable, run_square_wave

        cfg = config_from_args(args)
        sw = SquareWave(args.amplitude, args.hz, args.duration, args.holding_hz)
        if not all(0 < v < math.inf for v in (sw.amplitude, sw.hz, sw.duration_s, sw.holding_hz)):
            raise ConfigError("--amplitude, --hz, --duration and --holding-hz must be positive and finite")
        rec, log = run_square_wave(cfg, sw)
        if args.force_lag is None:
            from servo.experiments.square_wave import force_lag

            lag = force_lag(cfg)
        rec.source = f"simulated drive, {sw.amplitude * 1e3:g} mA {sw.hz:g} Hz square wave, {sw.holding_hz:g} Hz holding loop"
        reference = {"drive": nominal(cfg),
                     "model (3) of the drive": {p: representable(cfg, log, p, settings) for p in ("robust", "paper")}}
    else:
        if not args.recording:
            raise ConfigError("give a RECORDING (CSV, NPZ or .mat) or --simulate")
        rec = recording_from_args(args)
    paths = {"robust": ("robust",), "paper": ("paper",), "both": ("robust", "paper")}[
        args.path or ("both" if rec.v is not None else "robust")
    ]
    from servo.io.provenance import provenance

    prov = provenance(cfg if args.simulate else None, [] if args.simulate else [args.recording], args.argv)
    with staged(out) as tmp:  # the folder appears complete, or not at all
        summary = run_identify(rec, tmp, paths, terms, settings, args.force_unit or "A", reference, lag, prov,
                               args.position_unit or "m")  # fmt: skip
        if args.simulate:
            from servo.identify.job import paper_path_note

            save_recording_csv(tmp / "recording.csv", rec)
            summary["files"] = sorted(summary["files"] + ["recording.csv"])
            note = paper_path_note(summary, has_modes=bool(cfg.drive.mode_hz))
            if note:
                summary["notes"] = {"paper": note}
            write_json(tmp / "summary.json", summary)
    print(format_summary(summary, out))
    return 0

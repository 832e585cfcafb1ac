"""``servo hysteresis``: the pivot's hysteresis loop, its Dahl fit (eq. 6-7, paper Fig. 2-3)
and the large-range average slope (eq. 11, Fig. 4)."""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from servo.cli.common import (
    add_config_options, add_quiet_option, add_recording_options, config_from_args, progress_from_args, recording_from_args,
)
from servo.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "hysteresis",
        help="hysteresis loop: Dahl fit (sigma, Ha, alpha) and large-range average slope",
        description="Fit the simplified Dahl model (paper eq. 6-7) to the current-vs-position loop of a recording "
        "(t,u,x,v), or run the paper's experiments on the simulated drive (--simulate): an amplitude-modulated sine "
        "current under the PI holding loop (Fig. 2-3) and a large-range loop whose average slope is the bearing "
        "stiffness (eq. 11, Fig. 4). Writes summary.json, CSVs and PNGs.",
    )
    add_recording_options(p, optional=True)
    p.add_argument("--deadband", type=float, default=None,
                   help="velocity deadband for the direction, m/s (default: controller.direction_deadband)")  # fmt: skip
    p.add_argument("--fix-alpha", type=float, metavar="ALPHA", help="hold alpha at this value instead of fitting it")
    p.add_argument("--slope", action="store_true", help="recording: also fit the average slope (eq. 11)")
    p.add_argument("--simulate", action="store_true", help="run the experiments on the simulated drive")
    p.add_argument("--amplitude", type=float, default=6e-3, help="--simulate: AM sine peak current, A (default 0.006)")
    p.add_argument("--hz", type=float, default=5.0, help="--simulate: AM sine carrier frequency (default 5)")
    p.add_argument("--duration", type=float, default=2.0, help="--simulate: AM sine record length, s (default 2)")
    p.add_argument("--large-amplitude", type=float, default=5e-3, help="--simulate: large-loop triangle amplitude, m (default 0.005)")
    p.add_argument("--large-hz", type=float, default=0.5, help="--simulate: large-loop frequency (default 0.5)")
    add_config_options(p)
    p.add_argument("--out", metavar="DIR", help="output folder (default servo-out/hysteresis-<time>)")
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.io.progress import reporting

    with reporting(progress_from_args(args, "servo hysteresis")):  # --quiet: no progress or compile lines
        return _handle(args)


def _handle(args: argparse.Namespace) -> int:
    from servo.io.outdir import staged
    from servo.experiments.hysteresis import HysteresisExperiment
    from servo.experiments.hysteresis_report import format_summary, run_hysteresis_recording, run_hysteresis_simulated

    from servo.io.provenance import provenance

    cfg = config_from_args(args)
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("hysteresis-%Y%m%d-%H%M%S")
    if args.fix_alpha is not None and not 0.1 <= args.fix_alpha <= 10:
        raise ConfigError("--fix-alpha must lie in [0.1, 10]")
    if args.simulate:
        if args.recording:
            raise ConfigError("give a recording or --simulate, not both")
        exp = HysteresisExperiment(args.amplitude, args.hz, args.duration, args.large_amplitude, args.large_hz)
        if not all(v > 0 and math.isfinite(v) for v in (exp.amplitude, exp.hz, exp.duration_s, exp.large_amplitude_m,
                                                        exp.large_hz)):  # (min() let a NaN through)
            raise ConfigError("--amplitude, --hz, --duration, --large-amplitude and --large-hz must be positive and finite")
        if exp.large_amplitude_m >= cfg.drive.stroke:
            raise ConfigError(f"--large-amplitude must stay inside the stroke (+-{cfg.drive.stroke:g} m)")
        with staged(out) as tmp:
            summary = run_hysteresis_simulated(cfg, tmp, exp, fit_alpha=args.fix_alpha is None,
                                               provenance=provenance(cfg, [], args.argv))  # fmt: skip
    else:
        if not args.recording:
            raise ConfigError("give a RECORDING (CSV, NPZ or .mat with t,u,x,v) or --simulate")
        rec = recording_from_args(args)
        deadband = cfg.controller.direction_deadband if args.deadband is None else args.deadband
        with staged(out) as tmp:
            summary = run_hysteresis_recording(rec, tmp, deadband, args.fix_alpha is None,
                                               1.0 if args.fix_alpha is None else args.fix_alpha, args.slope,
                                               provenance(None, [args.recording], args.argv))  # fmt: skip
    print(format_summary(summary, out))
    return 0

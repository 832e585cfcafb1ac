"""``servo bode``: swept-sine frequency response at several current levels, without and with
the compensator, on the simulated drive and a second drive (paper Fig. 7-10)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from servo.cli.common import add_config_options, add_quiet_option, config_from_args, levels_from_arg, progress_from_args
from servo.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "bode",
        help="swept-sine Bode (current -> position) at several levels, with and without compensation",
        description="Stepped-sine frequency response from VCM current to position under the PI holding loop, at "
        "four or more input current levels, without and with the paper's compensator (Fig. 7-8), and the same "
        "compensator on a second drive (Fig. 9-10). Prints the resonance per level and the double-integrator "
        "figures; writes bode.csv, frd.npz (servo.io.frequency_response.load_frequency_responses, convertible to "
        "control.FrequencyResponseData), PNGs and summary.json.",
    )
    p.add_argument("--levels", default="0.2,1,4,16", metavar="MA,...", help="excitation amplitudes in mA (default 0.2,1,4,16)")
    p.add_argument("--f-min", type=float, default=10.0, help="lowest frequency, Hz (default 10)")
    p.add_argument("--f-max", type=float, default=1000.0, help="highest frequency, Hz (default 1000)")
    p.add_argument("--n-freq", type=int, default=30, help="log-spaced frequencies (default 30)")
    p.add_argument("--periods", type=int, default=8, help="measured periods per frequency (default 8)")
    p.add_argument("--no-second-drive", action="store_true", help="skip the second drive (Fig. 9-10)")
    add_config_options(p)
    p.add_argument("--out", metavar="DIR", help="output folder (default servo-out/bode-<time>)")
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def settings_from_args(args) -> "SweepSettings":  # noqa: F821
    from servo.experiments.bode import SweepSettings

    levels = levels_from_arg(args.levels)
    if not 0 < args.f_min < args.f_max:
        raise ConfigError("need 0 < --f-min < --f-max")
    if args.n_freq < 2 or args.periods < 2:
        raise ConfigError("--n-freq and --periods must be at least 2")
    return SweepSettings(levels=levels, f_min=args.f_min, f_max=args.f_max, n_freq=args.n_freq, periods=args.periods)


def handle(args: argparse.Namespace) -> int:
    from servo.io.outdir import staged
    from servo.experiments.bode_report import format_summary, run_bode

    cfg = config_from_args(args)
    s = settings_from_args(args)
    if s.f_max >= cfg.run.sample_rate_hz / 4:
        raise ConfigError(f"--f-max must stay below a quarter of the sample rate ({cfg.run.sample_rate_hz / 4:g} Hz)")
    if max(s.levels) > cfg.controller.current_limit:
        raise ConfigError("a level exceeds the current limit")
    from servo.experiments.bode import check_settings

    try:
        check_settings(s, cfg.run.sample_rate_hz)
    except ValueError as exc:
        raise ConfigError(f"bode: {exc}") from None
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("bode-%Y%m%d-%H%M%S")
    from servo.io.progress import reporting
    from servo.io.provenance import provenance

    with reporting(progress_from_args(args, "servo bode")), staged(out) as tmp:
        summary = run_bode(cfg, tmp, s, with_second=not args.no_second_drive, provenance=provenance(cfg, [], args.argv))
    print(format_summary(summary, out))
    return 0

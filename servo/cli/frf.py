"""``servo frf``: the frequency response from ``u`` to ``x`` of a recording."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from servo.cli.common import (add_position_unit_option, add_quiet_option, add_recording_options, progress_from_args,
                              recording_from_args)
from servo.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "frf",
        help="frequency response (u -> x) of a recording, with coherence and error bounds",
        description="Estimate the frequency response from the input u to the position x of a recording over Welch "
        "segments: H1 = P_ux/P_uu (open loop) or, with --closed-loop, P_rx/P_ru with the reference r (or an "
        "excitation injected in the loop) as instrument, which the feedback of noise does not bias. Writes frf.npz "
        "(servo.io.frequency_response.load_frequency_responses; .to_control() gives a "
        "control.FrequencyResponseData), frf.csv, frf.png and summary.json.",
    )
    add_recording_options(p)
    p.add_argument("--closed-loop", action="store_true", help="use the column r as instrument (map it with --columns r=NAME)")
    p.add_argument("--nperseg", type=int, help="samples per Welch segment (default: the largest power of two leaving 8 segments)")
    p.add_argument("--overlap", type=float, default=0.5, help="segment overlap, fraction (default 0.5)")
    p.add_argument("--window", default="hann", help="window (scipy.signal.get_window name, default hann)")
    p.add_argument("--detrend", choices=("constant", "linear"), default="constant", help="per segment (default constant)")
    p.add_argument("--f-min", type=float, default=0.0, help="lowest frequency written, Hz (default: the first line)")
    p.add_argument("--f-max", type=float, default=float("inf"), help="highest frequency written, Hz (default: Nyquist)")
    p.add_argument("--force-unit", help="unit of u, for the response's unit m/UNIT (default: the unit the file "
                   "declares, u [N], else A)")  # fmt: skip
    add_position_unit_option(p)
    p.add_argument("--out", metavar="DIR", help="output folder (default servo-out/frf-<time>)")
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.io.progress import reporting

    with reporting(progress_from_args(args, "servo frf")):  # --quiet: no progress or compile lines
        return _handle(args)


def _handle(args: argparse.Namespace) -> int:
    from servo.frf.estimate import WelchSettings
    from servo.frf.job import estimate_frf, format_summary, write_frf

    if args.nperseg is not None and args.nperseg < 8:
        raise ConfigError(f"--nperseg {args.nperseg}: at least 8 samples")
    if not 0.0 <= args.f_min < args.f_max:  # NaN fails too
        raise ConfigError(f"--f-min {args.f_min:g} and --f-max {args.f_max:g}: need 0 <= --f-min < --f-max (Hz)")
    rec = recording_from_args(args)
    settings = WelchSettings(nperseg=args.nperseg, overlap=args.overlap, window=args.window, detrend=args.detrend)
    resp = estimate_frf(rec, args.closed_loop, settings, args.force_unit, args.f_min, args.f_max, args.position_unit)
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("frf-%Y%m%d-%H%M%S")
    from servo.io.provenance import provenance

    from servo.io.outdir import staged

    with staged(out) as tmp:  # the folder appears complete, or not at all
        summary = write_frf(resp, rec, tmp, {"provenance": provenance(None, [args.recording], args.argv)})
    print(format_summary(summary, out))
    return 0

"""``servo paper``: regenerate every figure of the paper's section IV with a report."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from servo.cli.common import add_config_options, add_quiet_option, config_from_args, progress_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "paper",
        help="regenerate every figure of the paper's section IV with a Markdown report",
        description="Run the hysteresis (Fig. 2-4), friction identification (Fig. 5) and Bode (Fig. 7-10) experiments "
        "on the simulated drive and write their figures and a REPORT.md that puts each next to the paper's claim.",
    )
    p.add_argument("--n-freq", type=int, default=30, help="Bode frequencies per sweep (default 30)")
    p.add_argument("--levels", default="0.2,1,4,16", metavar="MA,...", help="Bode levels in mA (default 0.2,1,4,16)")
    add_config_options(p)
    p.add_argument("--out", metavar="DIR", help="output folder (default servo-out/paper-<time>)")
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.io.outdir import staged
    from servo.cli.bode import settings_from_args
    from servo.experiments.paper import run_paper

    cfg = config_from_args(args)
    args.f_min, args.f_max, args.periods = 10.0, 1000.0, 8
    s = settings_from_args(args)
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("paper-%Y%m%d-%H%M%S")
    t0 = time.perf_counter()
    from servo.io.progress import reporting

    with reporting(progress_from_args(args, "servo paper")), staged(out) as tmp:
        summary = run_paper(cfg, tmp, s)
    c = summary["bode"]["linearity_compensated"]
    h = summary["hysteresis"]["error_pct"]
    print(f"servo paper: section IV regenerated in {time.perf_counter() - t0:.0f} s")
    print(f"  Fig. 3-4: Dahl fit sigma {h['sigma']:+.2f} %, Ha {h['Ha']:+.2f} %, alpha {h['alpha']:+.2f} %; large-loop K {h['K']:+.2f} %")
    fr = summary["identification"]["fits"]["robust"]["error_pct"]["model (3) of the drive"]
    print("  Fig. 5 (robust path vs what model (3) can represent of the drive): "
          + ", ".join(f"{k} {v:+.1f} %" for k, v in fr.items()))
    print("  Fig. 7: f_n per level " + ", ".join(f"{r['f_n_hz']:.0f} Hz" for r in summary["bode"]["resonance_uncompensated"]))
    print(f"  Fig. 8: spread {c['spread_db_max']:.2f} dB, slopes "
          + ", ".join(f"{v:.1f}" for v in c["slope_db_per_decade"].values())
          + f" dB/dec, phase {c['phase_deg_min']:.0f}..{c['phase_deg_max']:.0f} deg")
    print(f"  wrote {out}/REPORT.md and the figures in hysteresis/, identification/, bode/")
    return 0

"""``servo demo``: worked demonstrations that chain several commands; ``servo demo cancel``
runs the proof of issue 14 (diagnose -> compensate -> the paper's measurements, per term)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from servo.cli.common import add_config_options, add_quiet_option, config_from_args, progress_from_args
from servo.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser("demo", help="worked demonstrations that chain several commands (servo demo cancel)",
                       description="Worked demonstrations that chain several commands.")  # fmt: skip
    demos = p.add_subparsers(dest="demo", metavar="DEMO", parser_class=type(p))
    c = demos.add_parser(
        "cancel",
        help="per cancellable term: a drive with it, diagnose, compensate (paper's and augmented), the paper's "
        "measurements with both, one table",
        description="For each cancellable term (asymmetric friction, Stribeck, a position-periodic force, a "
        "position-dependent force constant, a Dahl pivot other than the nominal): a drive carrying it beyond the "
        "paper's model, an identification recording on it, servo diagnose, servo compensate twice (--paper and "
        "augmented), then the Bode-at-levels spread (Fig. 8) and servo run's step and tracking figures with both. "
        "Writes TABLE.md, summary.json, each diagnosis's report.json and the Bode figures into --out "
        "(docs/compensate.md, 'The proof, end to end').",
    )
    c.add_argument("--terms", metavar="NAME,...", help="only these cases (default all)")
    c.add_argument("--n-freq", type=int, default=30, help="Bode frequencies per sweep (default 30)")
    c.add_argument("--levels", default="0.2,1,4,16", metavar="MA,...", help="Bode levels in mA (default 0.2,1,4,16)")
    c.add_argument("--quick", action="store_true", help="the test suite's short settings (2 levels, 6 frequencies)")
    add_config_options(c)
    c.add_argument("--out", metavar="DIR", help="output folder (default servo-out/cancel-<time>)")
    add_quiet_option(c)
    c.set_defaults(handler=handle_cancel)
    p.set_defaults(handler=handle_none)


def handle_none(args: argparse.Namespace) -> int:
    raise ConfigError("demo: name the demonstration (servo demo cancel)")


def handle_cancel(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from servo.cli.bode import settings_from_args
    from servo.experiments.cancel import CASES, QUICK, ChainSettings
    from servo.experiments.cancel_report import run_chain
    from servo.io.outdir import staged
    from servo.io.progress import reporting

    cfg = config_from_args(args)
    names = None
    if args.terms:
        names = [n.strip() for n in args.terms.split(",") if n.strip()]
        bad = [n for n in names if n not in CASES]
        if bad or not names:
            raise ConfigError(f"--terms: unknown {', '.join(bad) or 'nothing'}; one of {', '.join(CASES)}")
    if args.quick:
        s = QUICK
    else:
        args.f_min, args.f_max, args.periods = 10.0, 1000.0, 8
        s = replace(ChainSettings(), sweep=settings_from_args(args))
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("cancel-%Y%m%d-%H%M%S")
    t0 = time.perf_counter()
    with reporting(progress_from_args(args, "servo demo cancel")), staged(out) as tmp:
        summary = run_chain(cfg, tmp, s, names)
    print(f"servo demo cancel: {len(summary['cases'])} terms in {time.perf_counter() - t0:.0f} s")
    print(f"  {'term':<26}{'found':>7}{'spread paper':>14}{'augmented':>11}{'step 1 paper':>18}{'augmented':>18}")
    for c in summary["cases"]:
        if c["before"] is None:
            print(f"  {c['case']:<26}{'yes' if c['found'] else 'no':>7}  {c['note']}")
            continue
        st = [c[k]["run"]["steps"][0] for k in ("before", "after")]
        cell = lambda x: f"{x['overshoot_pct']:.1f}%/" + ("never" if x["settling_ms"] is None else f"{x['settling_ms']:.1f}ms")  # noqa: E731
        print(f"  {c['case']:<26}{'yes' if c['found'] else 'no':>7}{c['before']['bode']['spread_db_max']:>11.2f} dB"
              f"{c['after']['bode']['spread_db_max']:>8.2f} dB{cell(st[0]):>18}{cell(st[1]):>18}")  # fmt: skip
    print(f"  wrote {out}/TABLE.md, summary.json and each term's report.json and Bode figures")
    return 0

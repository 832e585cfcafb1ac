"""``servo loop``: loop-shaping measurements (L, S, T) in closed loop, against the design."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from servo.cli.common import add_config_options, add_quiet_option, config_from_args, levels_from_arg, progress_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "loop",
        help="measure the open loop L, sensitivity S and T by stepped-sine injection, against the design",
        description="Stepped-sine injection of a current at the controller's output, in closed loop, on the "
        "simulated drive or a board (--port URL, e.g. `servo emulate`): the open loop L, the sensitivity S and "
        "the complementary sensitivity T, broken at the controller output (L = -U_pi/U_n) and at the current "
        "(L_u = -U_fb/U), with and without the compensator, set against the design C*P (the PI holding loop on "
        "the double integrator 1/(J s^2) and on the drive's linear model). Prints the crossover (the lowest 0 dB "
        "crossing), the phase margin there, the binding gain margin with its side and max|S| of each (servo.design."
        "margins; a design's over the whole band to Nyquist), and refuses (exit 3) a design whose closed loop is "
        "unstable; writes frd.npz (servo.io.frequency_response."
        "load_frequency_responses, convertible to control.FrequencyResponseData), loop.csv, loop.png, "
        "sensitivity.png and summary.json. docs/loop.md explains the signs and the estimator.",
    )
    p.add_argument("--compensator", choices=("on", "off", "both"), default=None,
                   help="measure with the compensator, without, or both (default: both when [compensator] "
                        "enabled, else off)")  # fmt: skip
    p.add_argument("--levels", default="0.2", metavar="MA,...", help="excitation amplitudes in mA (default 0.2)")
    p.add_argument("--f-min", type=float, default=20.0, help="lowest frequency, Hz (default 20)")
    p.add_argument("--f-max", type=float, default=None,
                   help="highest frequency, Hz (default: 40 %% of the Nyquist frequency, the highest a stepped sine "
                   "measures)")  # fmt: skip
    p.add_argument("--n-freq", type=int, default=25, help="log-spaced frequencies (default 25)")
    p.add_argument("--target-error", type=float, default=0.0, metavar="PCT",
                   help="adapt each frequency's amplitude (a pilot run, then scaled) to this relative random error of "
                   "L in %%, each --levels value then the cap (default 0: the levels as given)")  # fmt: skip
    p.add_argument("--periods", type=int, default=8, help="measured periods per frequency (default 8)")
    p.add_argument("--settle", type=float, default=0.02, metavar="S",
                   help="settling before each frequency's window, s (at least 4 periods; default 0.02)")  # fmt: skip
    p.add_argument("--port", metavar="URL", help="measure a board (or `servo emulate`) over this serial port "
                   "instead of the simulated drive; start the emulator without a scenario disturbance "
                   "(--set scenario.disturbance_amplitude=0)")  # fmt: skip
    add_config_options(p)
    add_quiet_option(p)
    p.add_argument("--out", metavar="DIR", help="output folder (default servo-out/loop-<time>)")
    p.set_defaults(handler=handle)


def settings_from_args(args) -> "LoopSettings":  # noqa: F821
    from servo.loop.measure import LoopSettings

    levels = levels_from_arg(args.levels)
    return LoopSettings(f_min=args.f_min, f_max=args.f_max, n_freq=args.n_freq, periods=args.periods,
                        settle_s=args.settle, levels=levels, target_rel_err=args.target_error / 100.0)  # fmt: skip  (f_max None: the highest, LoopSettings.check)


def handle(args: argparse.Namespace) -> int:
    from servo.io.outdir import check_output, staged
    from servo.io.provenance import provenance
    from servo.io.progress import reporting
    from servo.loop.job import check_designs_stable, format_summary, run_loop
    from servo.runtime.controller import compensation_runs

    cfg = config_from_args(args)
    s = settings_from_args(args).check(cfg)
    checked = check_designs_stable(cfg, compensation_runs(cfg, args.compensator))  # an unstable design: nothing runs
    out = Path(args.out) if args.out else Path("servo-out") / time.strftime("loop-%Y%m%d-%H%M%S")
    check_output(out)
    prov = provenance(cfg, [], getattr(args, "argv", None))
    if args.port is None:
        with staged(out) as tmp:
            with reporting(progress_from_args(args, "servo loop")):  # closed before the summary
                summary = run_loop(cfg, tmp, s, args.compensator, provenance=prov, checked=checked)
    else:
        with reporting(progress_from_args(args, "servo loop")):
            summary = _on_port(cfg, out, s, args, prov, checked)
    print(format_summary(summary, out))
    return 0


def _on_port(cfg, out: Path, s, args: argparse.Namespace, prov: dict, checked: dict) -> dict:
    """The same job through the serial link: one session (driver) per run.  The first
    driver is configured (handshake, version and rate checks) before anything is written,
    so a bad URL or an absent board leaves no output folder."""
    from hil.serialdriver import Sessions
    from servo.io.outdir import staged
    from servo.loop.job import run_loop
    from servo.runtime.pacing import realtime_section

    # no GC pauses while the board waits; the collection that pauses it before the board is put in READY
    with realtime_section(), Sessions(cfg, args.port) as ports, staged(out) as tmp:
        return run_loop(cfg, tmp, s, args.compensator, make_driver=ports.make_driver, where=ports.where(cfg),
                        provenance=prov, checked=checked)

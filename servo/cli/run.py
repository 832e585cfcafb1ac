"""``servo run``: the closed loop (PI holding loop + compensator) on the simulated drive."""
from __future__ import annotations

import argparse
import math
from functools import partial
from pathlib import Path

from servo.cli import UsageError
from servo.cli.common import add_config_options, add_quiet_option, config_from_args, progress_from_args
from servo.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run the closed loop against the simulated drive (or a board: --port URL)",
        description="Run the closed loop (PI holding loop plus the paper's compensator) against the simulated "
        "drive: hold, reference steps, a sinusoidal disturbance. Prints a summary; writes logs, summary.json "
        "and PNG plots into the output folder.",
    )
    add_config_options(p)
    p.add_argument("--duration", type=float, metavar="S", help="simulated seconds (default: run.duration_s)")
    p.add_argument("--seed", type=int, help="sensor-noise seed (default: run.seed)")
    p.add_argument("--out", metavar="DIR", help="output folder, new or empty (default: servo-out/run-<time>); "
                   "written as DIR.incomplete/ and renamed when complete")  # fmt: skip
    p.add_argument("--log-format", choices=("npz", "csv", "both"), default="both",
                   help="run log files to write (default both)")  # fmt: skip
    p.add_argument("--compensation", choices=("on", "off", "compare"), default=None,
                   help="run with the compensator, without, or both and compare (default: compare when "
                        "[compensator] enabled, else off)")  # fmt: skip
    p.add_argument("--fast", action=argparse.BooleanOptionalAction, default=None,
                   help="all-compiled fast path instead of tick by tick (default: run.fast_path)")  # fmt: skip
    add_quiet_option(p)
    p.add_argument("--port", metavar="URL", help="run against a DSP/VCM board (or `servo emulate`) over this "
                   "pyserial URL: a device or pseudo-terminal path, socket://HOST:PORT, ... (the [link] section "
                   "sets latency, batching, timeouts)")  # fmt: skip
    p.add_argument("--loop-on-board", action="store_true", help="with --port: the board runs the controller kind "
                   "itself; the host sends the references and records the board's log (link.loop = \"board\"; a "
                   "lockstep board such as the reference firmware, docs/firmware.md)")  # fmt: skip
    p.add_argument("--gains", action="append", metavar="S=TOML", default=[],
                   help="with --loop-on-board: from S seconds into the run, the gains of the [controller] table of "
                        "the TOML file (same kind; repeat for more changes; the board applies each at its tick and "
                        "acknowledges it)")  # fmt: skip
    rt = p.add_argument_group(
        "real-time pacing",
        "Pace each tick on the wall clock at the sample rate (absolute deadlines, sleep then spin), as against "
        "a plant that lives in real time. Implies the tick path (the fast path cannot be paced); the numbers "
        "are the same as unpaced. Reports the lateness of each tick (p50/p99/p99.9/max) and the overruns, "
        "and writes lateness.png.",
    )
    rt.add_argument("--realtime", action="store_true", help="pace the run in real time")
    rt.add_argument("--overrun-policy", choices=("count", "fault"), default=None,
                    help="count overruns and continue (default), or fault: stop with the drive at zero current "
                         "after --max-overruns overruns in a row")  # fmt: skip
    rt.add_argument("--max-overruns", type=int, metavar="N", help="consecutive overruns that fault (default 10)")
    rt.add_argument("--cpu", type=int, metavar="N", help="pin the process to CPU core N")
    rt.add_argument("--fifo", type=int, metavar="PRIO", help="SCHED_FIFO at priority PRIO (1-99), if permitted")
    rt.add_argument("--lock-memory", action="store_true", help="lock the process's memory (mlockall), if permitted")
    rt.add_argument("--spin-us", type=float, metavar="US", help="spin instead of sleeping for the last US "
                    "microseconds before each deadline (default 100)")  # fmt: skip
    p.set_defaults(handler=handle)


REALTIME_ONLY = ("overrun_policy", "max_overruns", "cpu", "fifo", "lock_memory", "spin_us")


def realtime_options(args: argparse.Namespace):
    """The :class:`~servo.run.realtime.RealtimeOptions` of the command line, or None."""
    from servo.run.realtime import RealtimeOptions, check_realtime

    given = [n for n in REALTIME_ONLY if getattr(args, n) is not None and getattr(args, n) is not False]
    if not (args.realtime or given):
        return None
    option = "--realtime" if args.realtime else f"--{given[0].replace('_', '-')}"
    if not args.realtime and args.port is None:
        raise UsageError(f"servo run: {option} needs --realtime")
    try:
        check_realtime(True, args.fast, args.port is not None, option)
    except ConfigError as exc:
        raise UsageError(f"servo run: {exc}") from None
    d = RealtimeOptions()
    return RealtimeOptions(
        policy=args.overrun_policy or d.policy,
        max_overruns=d.max_overruns if args.max_overruns is None else args.max_overruns,
        cpu=args.cpu, fifo_priority=args.fifo, lock_memory=args.lock_memory,
        spin_s=d.spin_s if args.spin_us is None else args.spin_us * 1e-6,
    ).check()  # fmt: skip


def handle(args: argparse.Namespace) -> int:
    from servo.io.outdir import check_output, staged
    from servo.io.progress import reporting
    from servo.run.job import default_out_dir, format_summary, prepare, run_job

    realtime = realtime_options(args)
    cfg = config_from_args(args, run={"duration_s": args.duration, "seed": args.seed},
                           link={"loop": "board" if args.loop_on_board else None})  # fmt: skip
    gains = _gain_changes(cfg, args)
    out = Path(args.out) if args.out else default_out_dir()
    formats = ("npz", "csv") if args.log_format == "both" else (args.log_format,)
    check_output(out)
    inputs = prepare(cfg, simulated=args.port is None)  # what the config can be refused for, before any folder
    from servo.io.provenance import provenance

    prov = partial(provenance, cfg, [], getattr(args, "argv", None))  # made after the runs: its git calls fork
    with reporting(progress_from_args(args, "servo run")):  # closed (its line cleared) before the summary
        if args.port is None:
            with staged(out, keep_partial="log_*") as tmp:
                summary = run_job(cfg, tmp, compensation=args.compensation, fast=False if realtime else args.fast,
                                  realtime=realtime, log_formats=formats, provenance=prov, inputs=inputs)  # fmt: skip
        else:
            summary = _run_on_port(cfg, out, args, formats, prov, inputs, gains)
    print(format_summary(summary, out))
    return 0


def _gain_changes(cfg, args: argparse.Namespace) -> list:
    """The ``--gains S=TOML`` changes (:func:`hil.onboard.gain_changes_from_files`)."""
    if not args.gains:
        return []
    if args.port is None or cfg.link.loop != "board":
        raise UsageError("servo run: --gains needs --port URL and --loop-on-board (the board changes its gains)")
    changes = []
    for spec in args.gains:
        t, sep, path = spec.partition("=")
        try:
            t_s = float(t)
        except ValueError:
            t_s = math.nan
        if not sep or not path or not (math.isfinite(t_s) and t_s >= 0.0):
            raise UsageError(f"servo run: --gains {spec!r}: give S=TOML, seconds into the run and a TOML file")
        changes.append((t_s, path))
    from hil.onboard import gain_changes_from_files

    return gain_changes_from_files(cfg, changes)


def _run_on_port(cfg, out: Path, args: argparse.Namespace, formats: tuple[str, ...], prov, inputs,
                 gains=()) -> dict:  # fmt: skip
    """The same job against the serial link: a fresh session (driver) per run.  The first
    driver is configured (handshake, version and rate checks) before anything is written,
    so a bad URL or an absent board leaves no output folder."""
    from servo.io.outdir import staged
    from hil.onboard import OnBoardDriver
    from hil.serialdriver import SerialDriver, Sessions
    from servo.run.job import run_job
    from servo.runtime.pacing import realtime_section

    if args.fast or (args.fast is None and cfg.run.fast_path):
        raise UsageError("servo run: --port runs tick by tick through the link; drop --fast (run.fast_path)")
    # the collection that pauses the garbage collector comes before the board is put in READY
    driver = partial(OnBoardDriver, gains=gains) if cfg.link.loop == "board" else SerialDriver
    with realtime_section(), Sessions(cfg, args.port, driver) as ports, staged(out, keep_partial="log_*") as tmp:
        return run_job(cfg, tmp, compensation=args.compensation, fast=False, make_driver=ports.make_driver,
                       where=ports.where(cfg), log_formats=formats, provenance=prov, inputs=inputs)  # no GC pauses while the board waits

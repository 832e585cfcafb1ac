"""``servo fleet``: identify, diagnose or simulate many drives at once, on Dask.

``servo fleet identify|diagnose RECORDINGS...`` (paths, globs, ``--manifest FILE``),
``servo fleet simulate`` (a Monte Carlo fleet drawn from distributions over ``[drive]``),
``servo fleet synthetic`` (a fleet of recordings with known defects, for tests and
demos).  The work is :mod:`servo.fleet`; this module only parses.
"""
from __future__ import annotations

import argparse
import time
import tomllib
from pathlib import Path

from servo.cli.common import add_config_options, add_quiet_option, config_from_args, progress_from_args
from servo.cli.diagnose import add_decimate_option, parse_decimate
from servo.errors import ConfigError, ServoError


def _where_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("where it runs")
    g.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this existing Dask cluster (its workers "
                   "must import servo and read the recordings' paths)")  # fmt: skip
    g.add_argument("--workers", type=int, metavar="N", help="size of the local Dask cluster (default: one per CPU; "
                   "0: in this process; a handful of drives always run in this process)")  # fmt: skip
    g.add_argument("--batch", type=int, metavar="N", help="drives per Dask task (default: the command's)")
    p.add_argument("--resume", metavar="DIR", help="take the drives of the earlier fleet in DIR (or of the one "
                   "interrupted there) whose recording, content, mapping, scales, settings and versions match; run "
                   "only the others (--out DIR too: continue an interrupted fleet in place)")  # fmt: skip
    p.add_argument("--no-plots", action="store_true", help="write the table, fleet.json and fleet_report.md only")
    add_quiet_option(p)
    p.add_argument("--out", metavar="DIR", help="output folder, new or empty (default servo-out/fleet-<command>-<time>)")


def _recording_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("recordings", nargs="*", metavar="RECORDING", help="CSV, NPZ or .mat recordings, or globs ('*.npz')")
    p.add_argument("--manifest", metavar="FILE", help="CSV with a path column (and drive, columns, scale columns)")
    p.add_argument("--columns", metavar="ROLE=NAME,...", help="map t,u,x,v to names in the files, e.g. u=vir,x=qm")
    p.add_argument("--scale", metavar="ROLE=FACTOR,...", help="scale columns by a number or a scalar variable")
    p.add_argument("--cutoff-hz", type=float, help="robust path: Butterworth cutoff on position (default fs/decimation)")


def register(sub) -> None:
    p = sub.add_parser(
        "fleet",
        help="identify, diagnose or simulate a fleet of drives on Dask (local cluster by default)",
        description="Run one command over many drives: one Dask task per recording or drive, on a local cluster "
        "sized to the machine, an existing cluster (--scheduler), or this process. Writes fleet.parquet (one row "
        "per drive), fleet_report.md (failures, findings, robust outliers), fleet.json and population plots.",
    )
    fs = p.add_subparsers(dest="fleet_command", metavar="COMMAND", parser_class=type(p))
    fs.required = True

    q = fs.add_parser("identify", help="least squares of eq. (4) on every recording",
                      description="servo identify's robust (or paper) least squares on every recording; one row each.")
    _recording_options(q)
    q.add_argument("--path", choices=("robust", "paper"), default="robust", help="derivative path (default robust)")
    q.add_argument("--terms", metavar="T,...", help="terms to identify (default J,B,Fc,K,h0)")
    q.add_argument("--off", metavar="T,...", help="terms to switch off, e.g. K")
    q.add_argument("--force-lag", type=float, metavar="S", default=0.0, help="seconds the recorded force acts late")
    q.add_argument("--decimate", type=int, default=10, help="robust path: parallel decimation factor (default 10, "
                   "as servo identify's; 1 = none)")  # fmt: skip
    _where_options(q)
    q.set_defaults(handler=_reported(identify))

    q = fs.add_parser("diagnose", help="diagnose every recording: which drives carry physics the model lacks",
                      description="servo diagnose on every recording; one row each (findings, verdict, final model).")
    _recording_options(q)
    q.add_argument("--baseline", metavar="TERMS", help="terms of eq. 3 fitted on the training part (default J,B,Fc,K,h0)")
    q.add_argument("--test-fraction", type=float, default=0.25, help="fraction held out at the end (default 0.25)")
    q.add_argument("--blocks", type=int, default=10, help="cross-validation blocks (default 10)")
    q.add_argument("--alpha", type=float, default=0.05, help="family-wise false-alarm level per drive (default 0.05)")
    q.add_argument("--horizon", type=float, metavar="S", help="simulated-output horizon, s (default 10 row spacings)")
    q.add_argument("--force-unit", default="A", help="unit of the input column (default A)")
    add_decimate_option(q)  # servo diagnose's, default included
    _where_options(q)
    q.set_defaults(handler=_reported(diagnose))

    q = fs.add_parser("simulate", help="Monte Carlo: drives drawn from distributions, compensator on and off",
                      description="Draw --drives drives from distributions over [drive] fields (--vary "
                      "drive.Fc='normal(1e-3, 10%)', uniform(LO, HI), lognormal(MEDIAN, S)) and run each through "
                      "the servo run scenario on the all-compiled fast path, with and without the compensator; one "
                      "row each with step, settling and tracking figures.")  # fmt: skip
    q.add_argument("--drives", type=int, default=100, help="drives to draw (default 100)")
    q.add_argument("--vary", metavar="drive.KEY=SPEC", action="append", help="a field's distribution (repeatable)")
    q.add_argument("--spread", metavar="FILE", help="TOML with a [drive] table of distributions, e.g. Fc = \"normal(1e-3, 10%%)\"")
    q.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    q.add_argument("--duration", type=float, metavar="S", help="simulated seconds per run (default: run.duration_s)")
    add_config_options(q)
    _where_options(q)
    q.set_defaults(handler=_reported(simulate))

    q = fs.add_parser("synthetic", help="write a fleet of recordings with spreads and a few known defects",
                      description="Recordings of drives with parameter spreads, a known few carrying a concealed "
                      "defect (hysteresis, a resonance, an input saturation, an asymmetric friction), with "
                      "manifest.csv and truth.json: the input of servo fleet diagnose --manifest.")  # fmt: skip
    q.add_argument("--drives", type=int, default=50, help="drives (default 50)")
    q.add_argument("--defects", type=int, help="drives with a defect (default 5 %%, at least 1)")
    q.add_argument("--duration", type=float, default=1.0, metavar="S", help="seconds per recording (default 1)")
    q.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    q.add_argument("--out", metavar="DIR", required=True, help="output folder")
    add_quiet_option(q)
    q.set_defaults(handler=_reported(synthetic))


def _out(args, command: str) -> Path:
    return Path(args.out) if args.out else Path("servo-out") / time.strftime(f"fleet-{command}-%Y%m%d-%H%M%S")


def _run(args, command: str, tasks, settings: dict) -> tuple[str, ServoError | None]:
    from servo.fleet.job import format_summary, run_fleet
    from servo.fleet.runner import Progress, Where
    from servo.io.progress import current

    where = Where(args.scheduler, args.workers, args.batch)
    where.check()
    out = _out(args, command)
    summary = run_fleet(command, tasks, settings, out, where, args.resume, not args.no_plots,
                        Progress(current(), len(tasks)))  # fmt: skip
    failed = ServoError(f"fleet: every drive failed (see {out / 'fleet_report.md'})") if summary["ok"] == 0 else None
    return format_summary(summary, out), failed


def _reported(work):
    """A subcommand's handler: ``work(args) -> (text, error or None)`` under the command's
    progress reporter (stderr; none with ``--quiet``), then ``text`` on stdout once the
    reporter is closed, then the error if there is one."""

    def handler(args: argparse.Namespace) -> int:
        from servo.io.progress import reporting, stage

        with reporting(progress_from_args(args, f"servo fleet {args.fleet_command}")):
            stage("reading the inputs")
            text, error = work(args)
        print(text)
        if error is not None:
            raise error
        return 0

    handler.__name__ = handler.__qualname__ = f"handle_{work.__name__}"
    return handler


def _sources(args):
    from servo.fleet.sources import sources

    return sources(args.recordings, args.manifest, args.columns, args.scale)


def identify(args: argparse.Namespace) -> tuple[str, ServoError | None]:
    from servo.fleet import identify
    from servo.fleet.sources import recording_tasks
    from servo.identify.regressors import RobustSettings, parse_terms

    if args.force_lag < 0:
        raise ConfigError("--force-lag must be >= 0")
    settings = identify.settings(args.path, parse_terms(args.terms, args.off),
                                 RobustSettings(cutoff_hz=args.cutoff_hz, decimate=args.decimate), args.force_lag)  # fmt: skip
    return _run(args, "identify", recording_tasks(_sources(args), settings), settings)


def diagnose(args: argparse.Namespace) -> tuple[str, ServoError | None]:
    from servo.diagnose.baseline import from_terms
    from servo.fleet import diagnose
    from servo.fleet.sources import recording_tasks

    if not 0.0 < args.alpha < 0.5:
        raise ConfigError(f"--alpha {args.alpha!r}: expected a level between 0 and 0.5")
    if args.horizon is not None and not args.horizon > 0:
        raise ConfigError(f"--horizon {args.horizon!r}: expected a positive number of seconds")
    if not 0.05 <= args.test_fraction <= 0.5:
        raise ConfigError(f"--test-fraction {args.test_fraction:g}: expected a fraction between 0.05 and 0.5")
    if args.blocks < 4:
        raise ConfigError(f"--blocks {args.blocks}: at least 4 cross-validation blocks are needed")
    from_terms(args.baseline)  # an unknown term is one line now, not an error in every row
    rule, q = parse_decimate(args.decimate)
    settings = diagnose.settings(args.baseline, args.test_fraction, args.blocks, args.alpha, args.horizon,
                                 args.cutoff_hz, q, args.force_unit, rule)  # fmt: skip
    return _run(args, "diagnose", recording_tasks(_sources(args), settings), settings)


def _specs(args) -> dict:
    specs: dict = {}
    if args.spread:
        try:
            doc = tomllib.loads(Path(args.spread).read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ConfigError(f"fleet: --spread {args.spread}: no such file") from None
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise ConfigError(f"fleet: --spread {args.spread}: {exc}") from None
        for section, table in doc.items():
            if not isinstance(table, dict):
                raise ConfigError(f"fleet: --spread {args.spread}: {section} must be a table ([drive])")
            specs.update({f"{section}.{k}": v for k, v in table.items()})
    for item in args.vary or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--vary {item!r}: expected drive.KEY=SPEC, e.g. drive.Fc='normal(1e-3, 10%)'")
        specs[key.strip()] = value.strip().strip("'\"")
    return specs


def simulate(args: argparse.Namespace) -> tuple[str, ServoError | None]:
    from servo.config import from_dict, to_dict
    from servo.fleet.task import check_size
    from servo.fleet import simulate
    from servo.fleet.spec import draw_drives, parse_specs

    if args.drives < 1:
        raise ConfigError(f"--drives {args.drives}: expected at least 1")
    check_size(args.drives)
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(f"--duration {args.duration!r}: expected a positive number of seconds")
    cfg = config_from_args(args, run={"duration_s": args.duration})
    dists = parse_specs(_specs(args))
    if not dists:
        raise ConfigError("fleet simulate: nothing varies; give --vary drive.KEY=SPEC or --spread FILE")
    base = to_dict(cfg)
    centre = {k: dict(v) for k, v in base.items()}
    centre["drive"].update({d.field: d.centre() for d in dists})
    try:
        from_dict(centre)
    except ConfigError as exc:
        raise ConfigError(f"fleet: the drive at the distributions' centres is not valid: {exc}") from None
    settings = simulate.settings(base, {d.key: d.text for d in dists}, args.seed, getattr(args, "plugin", None))
    drives = draw_drives(dists, args.drives, args.seed)
    return _run(args, "simulate", simulate.drive_tasks(drives, settings), settings)


def synthetic(args: argparse.Namespace) -> tuple[str, ServoError | None]:
    from servo.fleet.synthetic import check_duration, synthetic_drives, write_fleet
    from servo.fleet.task import check_size

    check_duration(args.duration)
    check_size(args.drives)
    k = args.defects if args.defects is not None else max(1, round(0.05 * args.drives))
    drives = synthetic_drives(args.drives, k, args.seed)
    manifest = write_fleet(args.out, drives, args.duration)
    bad = [f"{d.name} ({d.defect})" for d in drives if d.defect]
    return "\n".join([f"servo fleet synthetic: {len(drives)} drives, {len(bad)} with a defect: {', '.join(bad) or 'none'}",
                      f"  wrote {args.out}/: {len(drives)} recordings, manifest.csv, truth.json",
                      f"  next: servo fleet diagnose --manifest {manifest}"]), None  # fmt: skip

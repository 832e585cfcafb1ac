"""Options shared by several subcommands."""
from __future__ import annotations

import argparse

from servo.cli import parse_set
from servo.config import Config, from_dict, load_config, to_dict
from servo.errors import ConfigError


def add_config_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", help="TOML config (default: the built-in default drive and scenario)")
    p.add_argument("--set", metavar="SECTION.KEY=VALUE", action="append", help="override one config field (repeatable)")
    p.add_argument("--plugin", metavar="MODULE", action="append",
                   help="import MODULE and register the controller kinds it defines (repeatable; docs/controllers.md)")


def config_from_args(args: argparse.Namespace, **sections: dict) -> Config:
    """The config of ``--config`` and ``--set``, then the given section overrides."""
    from servo.controllers.plugins import load_plugins

    load_plugins(getattr(args, "plugin", None))
    cfg = load_config(args.config)
    data = to_dict(cfg)
    for name, values in parse_set(args.set).items():
        into = data.setdefault(name, {})
        for k, v in values.items():  # a kind's section is updated, not replaced
            into[k] = {**into[k], **v} if isinstance(v, dict) and isinstance(into.get(k), dict) else v
    for name, values in sections.items():
        data.setdefault(name, {}).update({k: v for k, v in values.items() if v is not None})
    return from_dict(data)


def add_recording_options(p: argparse.ArgumentParser, optional: bool = False) -> None:
    """The positional RECORDING (delimited text, NPZ, MAT v5/v7.3, HDF5) and its --columns/--scale mapping."""
    help_ = ("recording (CSV/TSV/TXT, NPZ, MAT v5 or v7.3, HDF5) with columns t,u,x[,v][,r] (map other names, "
             "struct.field or group/dataset, with --columns/--scale)")
    p.add_argument("recording", nargs="?" if optional else None, help=help_ + (" (omit with --simulate)" if optional else ""))
    p.add_argument("--columns", metavar="ROLE=NAME,...", help="map t,u,x,v,r to names in the file, e.g. u=vir,x=qm")
    p.add_argument("--scale", metavar="ROLE=FACTOR,...", help="scale columns by a number or a scalar variable, e.g. u=gtau")


def recording_from_args(args: argparse.Namespace):
    """Load and validate the recording of :func:`add_recording_options`.  A command with
    ``--force-unit`` not given takes the unit the file declares for ``u`` (a CSV header
    ``u [N]``), else A; one with ``--position-unit`` (:func:`add_position_unit_option`)
    not given, the file's unit of ``x``, else m: what it prints follows the data."""
    from servo.io.recording import load_recording, parse_mapping

    rec = load_recording(args.recording, parse_mapping(args.columns, "--columns"), parse_mapping(args.scale, "--scale"))
    declared = (rec.meta or {}).get("units") or {}
    if getattr(args, "force_unit", "") is None:
        args.force_unit = declared.get("u") or "A"
    if hasattr(args, "position_unit"):
        from servo.io.units import position_unit

        args.position_unit = position_unit(args.position_unit, declared.get("x"))
    return rec


def add_position_unit_option(p: argparse.ArgumentParser) -> None:
    """``--position-unit``: m, or rad for a rotary axis (:mod:`servo.io.units`)."""
    p.add_argument("--position-unit", choices=("m", "rad"), help="unit of the position column x: m, or rad for a "
                   "rotary axis (default: the unit the file declares, x [rad], else m)")  # fmt: skip


def levels_from_arg(text: str, option: str = "--levels") -> tuple:
    """Comma-separated current levels in mA -> a tuple in A; each must be positive."""
    try:
        levels = tuple(float(v) * 1e-3 for v in text.split(","))
    except ValueError:
        raise ConfigError(f"{option} {text!r}: expected comma-separated numbers in mA") from None
    if not all(v > 0 for v in levels):  # NaN fails too
        raise ConfigError(f"{option} must be positive")
    return levels


def add_quiet_option(p: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress lines on stderr (:mod:`servo.io.progress`)."""
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr (the summary on stdout stays)")


def progress_from_args(args: argparse.Namespace, label: str):
    """The reporter of a command: :data:`servo.io.progress.QUIET` with ``--quiet``, else a
    :class:`servo.io.progress.Reporter` on stderr labelled ``label`` (install it with
    :func:`servo.io.progress.reporting`)."""
    from servo.io.progress import QUIET, Reporter

    return QUIET if getattr(args, "quiet", False) else Reporter(label)

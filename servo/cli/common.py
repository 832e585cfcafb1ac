"""Options shared by several subcommands."""
from __future__ import annotations

import argparse

from servo.cli import parse_set
from servo.config import Config, from_dict, load_config, to_dict


def add_config_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", help="TOML config (default: the built-in default drive and scenario)")
    p.add_argument("--set", metavar="SECTION.KEY=VALUE", action="append", help="override one config field (repeatable)")


def config_from_args(args: argparse.Namespace, **sections: dict) -> Config:
    """The config of ``--config`` and ``--set``, then the given section overrides."""
    cfg = load_config(args.config)
    data = to_dict(cfg)
    for name, values in parse_set(args.set).items():
        data.setdefault(name, {}).update(values)
    for name, values in sections.items():
        data.setdefault(name, {}).update({k: v for k, v in values.items() if v is not None})
    return from_dict(data)

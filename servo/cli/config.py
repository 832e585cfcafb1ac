"""``servo config``: print the documented default config, or check a config file."""
from __future__ import annotations

import argparse

from servo.cli.common import add_config_options, config_from_args
from servo.config import to_markdown, to_toml


def register(sub) -> None:
    p = sub.add_parser("config", help="print the default config (documented) or check a file",
                       description="Print the complete configuration as TOML, every field with its unit and range. "
                       "With --config/--set, print the effective configuration after checking it.")  # fmt: skip
    add_config_options(p)
    p.add_argument("--markdown", action="store_true", help="print the field reference as Markdown (docs/config.md)")
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    if args.markdown:
        print(to_markdown())
        return 0
    print(to_toml(config_from_args(args)))
    return 0

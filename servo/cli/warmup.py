"""``servo warmup``: compile every kernel ahead, so that the first real command starts at once."""
from __future__ import annotations

import argparse

from servo.cli.common import add_quiet_option


def register(sub) -> None:
    p = sub.add_parser("warmup", help="compile every kernel ahead (the first run after an install or an edit)",
                       description="Compile (or load from the cache) every Numba kernel and every registered "
                       "controller kind's composed kernels, so that the next command starts at once. Takes 10-20 s "
                       "on an idle machine once after an install or an edit, about a second afterwards. The cache "
                       "is in the Python environment (var/cache/kernels-numba) unless SERVO_NUMBA_CACHE names a "
                       "folder.")  # fmt: skip
    add_quiet_option(p)
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.runtime.warmup import compile_all

    got = compile_all()
    print(f"servo warmup: {got['compiled']} kernels compiled, {got['loaded']} loaded from the cache, "
          f"{got['seconds']:.1f} s; cached in {got['cache']}")  # fmt: skip
    return 0

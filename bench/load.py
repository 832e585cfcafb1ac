"""Load the machine while something else runs: ``N`` processes spinning on the CPU.

Used to check that the asserted benchmarks hold when other processes share the machine
(CI runs beside other work)::

    python -m bench.load 1 -- python -m pytest bench     # one busy core
    python -m bench.load 2 -- python -m pytest bench     # both cores of a 2-core machine

Runs the command after ``--`` with the spinners going, stops them when it ends, and
exits with its status.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import subprocess
import sys


def _spin(parent: int) -> None:
    while os.getppid() == parent:  # ends with its parent, even one killed by a signal
        for _ in range(1_000_000):
            pass


def main(argv: list[str]) -> int:
    if "--" not in argv or argv.index("--") != 1 or not argv[0].isdigit() or len(argv) < 3:
        print("usage: python -m bench.load N -- COMMAND [ARGS...]", file=sys.stderr)
        return 2
    spinners = [mp.Process(target=_spin, args=(os.getpid(),), daemon=True) for _ in range(int(argv[0]))]
    for p in spinners:
        p.start()
    try:
        return subprocess.call(argv[2:])
    finally:
        for p in spinners:
            p.terminate()
            p.join()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

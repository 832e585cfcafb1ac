"""Instructions per tick of the tick path, by callgrind: a count a busy neighbour does not
change, where time cannot tell a slow process from a slow host.

    python -m bench.tick_instructions [--seed S]      # runs valgrind twice, prints the count

Runs ``servo run``'s default scenario tick by tick (:func:`servo.runtime.loop.run_closed_loop`,
run log on disk) for 2000 and for 6000 ticks under ``valgrind --tool=callgrind``, with
the instrumentation switched on just before the loop (``callgrind_control -i on``), and
prints the difference over 4000 ticks: the set-up, the run log's finalisation and the
interpreter's exit cancel.  ``--seed`` sets ``PYTHONHASHSEED`` (a process's hash seed is
the one thing of ours that differs between processes).  Each run takes minutes under
valgrind.  Needs ``valgrind`` on the PATH.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

SHORT, LONG = 2000, 6000


def _ticks(n: int) -> None:
    """Child: ``n`` ticks, instrumented from just before the loop to just after it."""
    from kernels.compose import LOG_COLUMNS
    from servo.config import Config
    from servo.io.runlog import RunLog
    from servo.runtime.controller import Controller
    from servo.runtime.loop import run_closed_loop
    from servo.runtime.simdriver import SimDriver
    from servo.scenarios import scenario_inputs

    cfg = Config().replace(run={"duration_s": n / Config().run.sample_rate_hz})
    inputs = scenario_inputs(cfg)
    drv = SimDriver(cfg, inputs)
    drv.configure()
    ctl = Controller(cfg)
    with tempfile.TemporaryDirectory() as tmp, RunLog(tmp, "r", LOG_COLUMNS) as log:
        subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], capture_output=True, check=True)
        run_closed_loop(cfg, drv, ctl, inputs, log, fast=False)
        subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], capture_output=True, check=True)


def instructions(n: int, seed: str, out: Path) -> int:
    """Instructions callgrind counted in a child running ``n`` ticks."""
    env = dict(os.environ, PYTHONHASHSEED=seed)
    r = subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}",
                        sys.executable, "-m", "bench.tick_instructions", "--child", str(n)],
                       env=env, capture_output=True, text=True)  # fmt: skip
    if r.returncode:
        raise SystemExit(f"valgrind: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode}")
    m = re.search(r"^totals:\s*(\d+)", out.read_text(), re.M)
    return int(m.group(1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.tick_instructions", description=__doc__.splitlines()[0])
    ap.add_argument("--seed", default="0", help="PYTHONHASHSEED of the runs (default 0)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        _ticks(a.child)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        short = instructions(SHORT, a.seed, Path(tmp) / "short.out")
        long = instructions(LONG, a.seed, Path(tmp) / "long.out")
    print(f"tick path: {(long - short) / (LONG - SHORT):.0f} instructions per tick (PYTHONHASHSEED={a.seed}; "
          f"{short} for {SHORT} ticks, {long} for {LONG})")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

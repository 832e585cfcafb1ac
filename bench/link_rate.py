"""The highest sample rate a real-time board sustains over the link with zero missed deadlines.

For each rate (ascending) this starts ``servo emulate --realtime`` (the clock master, on a
pseudo-terminal, pinned to one CPU), runs the closed loop against it from this process
(pinned to the other CPU, garbage collector frozen) for ``--seconds``, and reads the
board's counters: missed deadlines (a command not there at its tick), late commands,
and the emulator's own overruns (ticks it started late, reported, not judged: a real
board does not overrun).  A rate passes when the run completed with zero missed
deadlines and zero late commands.  The drive is the default one without flexible modes (so
that every rate is valid; their cost in the emulator is a few percent).

    python bench/link_rate.py --d 1 --b 1 --rates 1000,2000,3000,5000,7000,10000
    python bench/link_rate.py --d 16 --b 8 --rates 10000,20000,30000,40000,50000

Prints one line per rate and the highest passing rate.  Timing on a shared machine is
noisy: rerun on a quiet one for the figure that counts.
"""
from __future__ import annotations

import argparse
import os
import re
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hil.serialdriver import SerialDriver
from kernels.compose import LOG_COLUMNS
from servo.config import Config, to_toml
from servo.errors import DriverError
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.loop import run_closed_loop
from servo.runtime.pacing import realtime_section
from servo.scenarios import scenario_inputs


def one_rate(rate: float, d: int, b: int, seconds: float, cpus: tuple[int, int] | None, fifo: int | None,
             fifo_host: int | None = None) -> dict:  # fmt: skip
    cfg = Config().replace(
        run={"sample_rate_hz": rate, "duration_s": seconds},
        drive={"mode_hz": [], "mode_zeta": [], "mode_gain": []},
        link={"command_latency_ticks": d, "batch": b, "late_limit_ticks": min(65535, int(2.0 * rate)), "watchdog_s": 2.0, "timeout_s": 2.0},
    )
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "cfg.toml"
        f.write_text(to_toml(cfg))
        cmd = [sys.executable, "-m", "servo", "emulate", "--realtime", "--sessions", "1", "--config", str(f)]
        if cpus:
            cmd += ["--cpu", str(cpus[1])]
        if fifo:
            cmd += ["--fifo", str(fifo)]
        emu = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
        try:
            ready, _, _ = select.select([emu.stdout], [], [], 60)
            m = re.search(r"listening on (\S+)", emu.stdout.readline() if ready else "")
            if not m:
                raise RuntimeError("the emulator did not start")
            drv = SerialDriver(cfg, m.group(1))
            error = None
            with realtime_section(cpus[0] if cpus else None, fifo or fifo_host):
                try:
                    with drv, RunLog(tmp, "log", LOG_COLUMNS) as log:
                        run_closed_loop(cfg, drv, Controller(cfg), scenario_inputs(cfg), log, timing=False)
                except DriverError as exc:
                    error = str(exc)
            emu.wait(10)
            log_lines = emu.stdout.read()
        finally:
            if emu.poll() is None:
                emu.kill()
                emu.wait()
    st = drv.board_stats or {}
    ok = error is None and st.get("missed_deadlines", 1) == 0 and st.get("late_commands", 1) == 0 \
        and st.get("ticks", 0) >= cfg.n_ticks
    return {"rate": rate, "ok": ok, "error": error, "ticks": st.get("ticks"), "missed": st.get("missed_deadlines"),
            "late": st.get("late_commands"), "overruns": st.get("overruns"),
            "first_missed": (re.findall(r"first missed deadlines at ticks (\[[^\]]*\])", log_lines) or [""])[0]}


def stall_probe(cpus, seconds: float = 1.0) -> str:
    """The longest gap seen by a spinning loop pinned to each CPU: what the machine takes
    away from any user-space real-time loop (a quiet machine: well under 0.1 ms)."""
    old = os.sched_getaffinity(0)
    out = []
    try:
        for cpu in cpus or (None,):
            if cpu is not None:
                os.sched_setaffinity(0, {cpu})
            t = time.perf_counter_ns
            end, last, worst = t() + int(seconds * 1e9), t(), 0
            while last < end:
                now = t()
                worst = max(worst, now - last)
                last = now
            out.append(f"cpu {cpu}: {worst / 1e6:.2f} ms")
    finally:
        os.sched_setaffinity(0, old)
    return ", ".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--d", type=int, default=1, help="command latency, ticks")
    ap.add_argument("--b", type=int, default=1, help="samples per frame")
    ap.add_argument("--rates", default="1000,2000,3000,5000,7000,10000", help="comma-separated rates, Hz")
    ap.add_argument("--seconds", type=float, default=2.0, help="length of each run, s")
    ap.add_argument("--no-pin", action="store_true", help="do not pin host and emulator to CPUs 0 and 1")
    ap.add_argument("--fifo", type=int, help="SCHED_FIFO priority for both, if permitted")
    ap.add_argument("--fifo-host", type=int, help="SCHED_FIFO priority for the host only (it blocks, never spins)")
    ap.add_argument("--verbose", action="store_true", help="show the ticks of the first missed deadlines")
    args = ap.parse_args()
    cpus = None if args.no_pin or os.cpu_count() < 2 else (0, 1)
    best = None
    print(f"d = {args.d}, b = {args.b}, {args.seconds:g} s per rate, cpus {cpus}, fifo {args.fifo}, "
          f"fifo host {args.fifo_host}, load average {os.getloadavg()[0]:.2f}")
    print(f"longest stall of a pinned spinning loop in 1 s: {stall_probe(cpus)}", flush=True)
    for rate in sorted(float(r) for r in args.rates.split(",")):
        r = one_rate(rate, args.d, args.b, args.seconds, cpus, args.fifo, args.fifo_host)
        print(f"  {rate:>8.0f} Hz  {'ok  ' if r['ok'] else 'FAIL'}  ticks {r['ticks']}  missed {r['missed']}  "
              f"late {r['late']}  emulator overruns {r['overruns']}" + (f"  ({r['error']})" if r["error"] else "")
              + (f"  first missed at ticks {r['first_missed']}" if args.verbose and r["first_missed"] else ""),
              flush=True)  # fmt: skip
        if r["ok"]:
            best = rate
    print(f"highest rate with zero missed deadlines: {best:.0f} Hz" if best else "no rate passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())

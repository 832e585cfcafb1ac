"""Real-time runs (``servo run --realtime``): options, the paced section, the report.

A real-time run steps the tick path (read -> controller -> write -> tasks) with a
:class:`~servo.runtime.pacing.Pacer`: tick ``k`` starts at ``t0 + k*period`` on the wall clock,
waited for by sleeping, then spinning the last ``spin_s``.  The fast path cannot be
paced (it runs a block of ticks per compiled call), so ``--realtime`` implies the tick
path.  Pacing changes *when* a tick runs, never what it computes: the log of a paced run
is the log of the unpaced run, bit for bit.

What is reported per run: the lateness of each tick's start behind its deadline (us:
p50, p99, p99.9, max), the overruns (ticks that started after their deadline; with policy
``fault``, ``max_overruns`` in a row stop the run with the drive at zero current), and
what the OS granted (CPU affinity, ``SCHED_FIFO``, locked memory), one line for each
thing it refused.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servo.config import Config
from servo.errors import ConfigError
from servo.runtime.durations import Durations
from servo.runtime.pacing import Pacer, RealtimeGrant

#: Rows per run-log block in a paced run (or against a board): the journal's writer
#: thread writes and fsyncs each block; smaller blocks keep what a crash can lose, and
#: the thread's share of the interpreter lock per write, small.
REALTIME_LOG_BLOCK = 512


@dataclass(frozen=True)
class RealtimeOptions:
    """How to pace a run.  ``policy``: ``count`` (count overruns, continue) or ``fault``
    (stop after ``max_overruns`` consecutive overruns); ``cpu``: core to pin to;
    ``fifo_priority``: ``SCHED_FIFO`` priority (1-99); ``lock_memory``: ``mlockall``;
    ``spin_s``: how long before each deadline to stop sleeping and spin (s)."""

    policy: str = "count"
    max_overruns: int = 10
    cpu: int | None = None
    fifo_priority: int | None = None
    lock_memory: bool = False
    spin_s: float = 100e-6

    def check(self) -> "RealtimeOptions":
        """Raise :class:`~servo.errors.ConfigError` (one line) on a bad option."""
        if self.policy not in ("count", "fault"):
            raise ConfigError(f"realtime: overrun policy must be count or fault, got {self.policy!r}")
        if self.max_overruns < 1:
            raise ConfigError(f"realtime: --max-overruns must be >= 1, got {self.max_overruns}")
        if self.fifo_priority is not None and not 1 <= self.fifo_priority <= 99:
            raise ConfigError(f"realtime: --fifo priority must be within 1..99, got {self.fifo_priority}")
        if self.cpu is not None and (self.cpu < 0 or self.cpu >= (os.cpu_count() or 1)):
            raise ConfigError(f"realtime: --cpu {self.cpu}: this machine has cores 0..{(os.cpu_count() or 1) - 1}")
        if not 0.0 <= self.spin_s <= 1.0:
            raise ConfigError(f"realtime: --spin-us must be within 0..1e6, got {self.spin_s * 1e6:g}")
        return self


def check_realtime(realtime: bool, fast: bool | None, on_board: bool, option: str = "--realtime") -> None:
    """The rules of a paced run, in one place (``servo run``'s options and
    :func:`~servo.run.job.run_job` both call it): pacing is of the simulated drive (a board
    is its own clock), on the tick path (the fast path cannot be paced).  ``realtime``:
    pacing is asked for, by ``option`` (for the message); ``fast``: the fast path is asked
    for explicitly (None: the config decides, and pacing overrides it); ``on_board``: the
    loop runs against a board.  Raises :class:`~servo.errors.ConfigError` (one line)."""
    if not realtime:
        return
    if on_board:
        raise ConfigError(f"{option} is for pacing the simulated drive; with --port the board is the clock master "
                          "and paces the loop")  # fmt: skip
    if fast:
        raise ConfigError(f"{option} paces the tick path; the all-compiled fast path (--fast) runs blocks of ticks "
                          "per call and cannot be paced")  # fmt: skip


def make_pacer(cfg: Config, opts: RealtimeOptions) -> Pacer:
    """A pacer for ``cfg.n_ticks`` ticks at the config's sample period."""
    return Pacer(cfg.dt, cfg.n_ticks, spin_s=opts.spin_s, policy=opts.policy, max_consecutive=opts.max_overruns)


def granted(grant: RealtimeGrant) -> dict:
    """What the OS granted, as JSON-ready values; ``notes`` lists what it refused."""
    return {
        "gc_frozen": grant.gc_frozen,
        "cpu_affinity": grant.affinity,
        "sched_fifo": grant.sched_fifo,
        "memory_locked": grant.memory_locked,
        "notes": list(grant.notes),
    }


def report(pacer: Pacer, opts: RealtimeOptions, grant: RealtimeGrant) -> dict:
    """The summary of a paced run: lateness distribution (us), overruns, policy, grant."""
    return {**pacer.report(), "policy": opts.policy, "max_overruns": opts.max_overruns,
            "spin_us": opts.spin_s * 1e6, "granted": granted(grant)}  # fmt: skip


def grant_line(g: dict) -> str:
    """One line: what the run got from the OS."""
    parts = ["GC frozen" if g["gc_frozen"] else "GC on"]
    parts.append(f"pinned to core {g['cpu_affinity'][0]}" if g["cpu_affinity"] else "not pinned")
    parts.append("SCHED_FIFO" if g["sched_fifo"] else "normal scheduling")
    parts.append("memory locked" if g["memory_locked"] else "memory not locked")
    return ", ".join(parts)


def lateness_line(label: str, rt: dict, period_us: float) -> str:
    """One line: the lateness distribution and overruns of one paced run."""
    return (
        f"  lateness ({label}): p50 {rt['lateness_us_p50']:.2f} us, p99 {rt['lateness_us_p99']:.2f} us, "
        f"p99.9 {rt['lateness_us_p999']:.1f} us, max {rt['lateness_us_max']:.0f} us; "
        f"overruns (started after the deadline, period {period_us:g} us): {rt['overruns']} of {rt['ticks']} ticks"
    )


def plot_lateness(cfg: Config, lateness: dict[str, Durations], path: Path | None = None):
    """Histogram (a Figure) of the lateness of every tick (us, log-log; lateness below
    10 ns, including 0, is counted in the first bin), one curve per run, with the period
    and each run's p99.9 marked.  ``lateness``: label -> lateness per tick (ns, as
    :class:`~servo.runtime.durations.Durations`).  Written as PNG to ``path`` when given."""
    from servo.io.plotting import finish, subplots

    fig, ax = subplots(figsize=(8, 4.2))
    period = cfg.dt * 1e6
    colors = {"compensated": "tab:blue", "uncompensated": "tab:orange"}
    lo = 0.01
    hi = max(max(late.max / 1e3 for late in lateness.values()), period) * 1.2
    bins = np.logspace(np.log10(lo), np.log10(hi), 90)
    for label, late in lateness.items():
        edges_ns, counts = late.histogram()
        us = np.maximum(edges_ns / 1e3, lo)
        ax.hist(us, bins=bins, weights=counts, histtype="step", color=colors.get(label), label=f"{label} ({late.count} ticks)")
        ax.axvline(max(late.quantile(0.999) / 1e3, lo), color=colors.get(label), ls=":", lw=1, label=f"p99.9, {label}")
    ax.axvline(period, color="r", lw=1, label=f"period {period:g} us")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("lateness of the tick's start behind its deadline (us)")
    ax.set_ylabel("ticks")
    ax.set_title(f"Real-time pacing at {cfg.run.sample_rate_hz / 1e3:g} kHz: tick start lateness")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return finish(fig, path)

"""``servo run``: the closed loop against the simulated drive, summarised.

Runs the scenario of ``cfg.scenario`` (hold, reference steps, a sinusoidal force
disturbance) with the PI holding loop, with and/or without the compensator, and writes
into one output folder:

* ``log_compensated.{npz,csv}``, ``log_uncompensated.{npz,csv}``: the run logs;
* ``summary.json``: tracking error RMS per segment, per-step overshoot and settling,
  compute time per sample, ticks, overruns, the cold start (process start to first tick);
* ``tracking.png``, ``steps.png``, ``current.png`` (and ``timing.png`` tick by tick;
  ``lateness.png`` when paced in real time, see :mod:`servo.run.realtime`);
* ``config.toml``: the effective configuration (rerun it for the same bits);
* ``report.html``: all of it on one self-contained page (:mod:`servo.run.page`).
"""
from __future__ import annotations

import time
from contextlib import nullcontext
from pathlib import Path
from typing import Callable

import numpy as np

from kernels import _cache
from kernels.compose import LOG_COLUMNS
from servo.config import Config, to_toml
from servo.controllers import get_kind
from servo.io import progress
from servo.io.atomic import atomic_write, write_json
from servo.io.page import NAME as PAGE
from servo.io.provenance import or_default
from servo.io.resources import check_disk
from servo.io.runlog import FORMATS, RunLog
from servo.run.metrics import tick_timing
from servo.run.reduce import PesReport, PlotRows, RunFigures
from servo.run.realtime import REALTIME_LOG_BLOCK, RealtimeOptions, check_realtime, grant_line, lateness_line, make_pacer, plot_lateness, report
from servo.run.startup import process_age_s
from servo.runtime.controller import Controller, compensation_runs
from servo.runtime.driver import Driver
from servo.runtime.loop import LoopResult, log_rows, run_closed_loop
from servo.runtime.pacing import realtime_section
from servo.scenarios import Inputs, scenario_inputs
from servo.runtime.simdriver import SimDriver
from servo.runtime.simplant import build_plant

#: Rows per journal block of a simulated run (~0.8 MB): each block is one write and one fsync.
LOG_BLOCK = 8192


def default_out_dir() -> Path:
    return Path("servo-out") / time.strftime("run-%Y%m%d-%H%M%S")


def prepare(cfg: Config, simulated: bool = True) -> Inputs:
    """The run's inputs (:func:`~servo.scenarios.scenario_inputs`), built, and
    the simulated drive's plant checked (``simulated``): what a valid config can still
    be refused for when it runs (an excitation no signal meets, the HDD benchmark at a
    rate it does not divide, a holding current beyond the limit), raised before any
    file or folder is made."""
    if cfg.scenario.kind == "hdd_benchmark":
        PesReport(cfg)  # its settings checked before anything runs
    inputs = scenario_inputs(cfg)
    if simulated:
        build_plant(cfg.drive, cfg.dt)
    return inputs


def run_simulated(cfg: Config, out_dir: Path, compensated: bool, fast: bool,
                  make_driver: Callable[[Config, Inputs], Driver] | None = None,
                  realtime: RealtimeOptions | None = None,
                  log_formats: tuple[str, ...] = FORMATS, inputs: Inputs | None = None) -> tuple[dict, np.ndarray, LoopResult]:  # fmt: skip
    """One closed-loop run against a fresh driver (default: the simulated drive); returns
    (figures, plot rows, result): the run's tracking and step figures
    (:class:`~servo.run.reduce.RunFigures`), the rows its plots draw
    (:class:`~servo.run.reduce.PlotRows`), and the loop's result.  The log streams to
    ``log_<label>.journal`` while the run goes and is finalised into ``log_formats``
    after the driver is closed; the figures are computed in that same pass, so memory
    does not grow with the run.  What the driver reports (:meth:`Driver.report`: the
    serial link's frames and counters; None for the simulated drive) is recorded in
    ``result.link``.  ``realtime``: pace the ticks on the wall clock (tick path,
    simulated drive); the result then carries the pacing report and the lateness of
    every tick.  A run against a plant in real time (paced, or a board) journals its log
    in blocks of :data:`~servo.run.realtime.REALTIME_LOG_BLOCK` rows.  ``inputs``: the
    run's inputs as :func:`prepare` built them (built from ``cfg`` when None)."""
    label = "compensated" if compensated else "uncompensated"
    inputs = scenario_inputs(cfg) if inputs is None else inputs
    meta = {"label": label, "fast_path": fast, "sample_rate_hz": cfg.run.sample_rate_hz, "seed": cfg.run.seed,
            "realtime": realtime is not None}  # fmt: skip
    driver = SimDriver(cfg, inputs) if make_driver is None else make_driver(cfg, inputs)
    pacer = make_pacer(cfg, realtime) if realtime else None
    section = realtime_section(realtime.cpu, realtime.fifo_priority, realtime.lock_memory) if realtime else nullcontext()
    block = REALTIME_LOG_BLOCK if (realtime or make_driver is not None) else LOG_BLOCK
    controller = Controller(cfg, compensation=compensated)
    meta["controller"] = cfg.controller.kind
    figures, plot_rows = RunFigures(cfg), PlotRows(log_rows(cfg))
    log = RunLog(out_dir, f"log_{label}", controller.log_columns, meta, block, formats=log_formats,
                 units=controller.log_units)  # fmt: skip
    try:
        with driver:
            ticks = lambda: min(log.recorded_rows * cfg.run.log_every, cfg.n_ticks)  # noqa: E731  (progress)
            with section as grant, progress.watch(ticks):  # only around configure and the loop: the log is finalised outside
                result = run_closed_loop(cfg, driver, controller, inputs, log, fast=fast, pacer=pacer)
    except BaseException:
        log.close_after_fault()
        raise
    pes = PesReport(cfg) if cfg.scenario.kind == "hdd_benchmark" else None
    progress.stage(f"{label} run: writing the log", log.recorded_rows, "rows")
    log.finalise([figures, plot_rows, lambda rows: progress.advance(len(rows))] + ([pes] if pes else []))
    result.link = driver.report()
    figs = figures.result()
    if pes is not None:  # the HDD benchmark's figures, and their plot
        from servo.run.pes_plots import pes_plot

        got = pes.result()
        figs["pes_tracks"] = got.summary()
        atomic_write(out_dir / f"pes_{label}.png", lambda p: pes_plot(got, "track", f"PES, {label}").savefig(p, format="png"))
    if realtime:
        result.realtime = report(pacer, realtime, grant)
        result.lateness = pacer.lateness
    return figs, plot_rows.rows(), result


def summarise(cfg: Config, figures: dict, result: LoopResult) -> dict:
    """The summary of one run: its figures (:meth:`RunFigures.result`), compute time,
    and what the link and the pacer report."""
    out = {**figures, "wall_s": result.wall_s, "per_sample_us": result.wall_s / result.n_ticks * 1e6,
           "estimator_error_rms_m": result.error_rms}  # the on-line estimate, every run.estimator_every ticks
    if result.timing is not None:
        out.update(tick_timing(result.timing, cfg.dt))
    if result.link is not None:
        out["link"] = result.link
    if result.realtime is not None:
        out["realtime"] = result.realtime
    return out


def output_bytes(cfg: Config, runs: int, log_formats: tuple[str, ...]) -> float:
    """Disk bytes the logs of ``runs`` runs of ``cfg`` need at their peak (journal, NPZ
    column temporaries and NPZ, CSV at ~25 characters a value)."""
    values = log_rows(cfg) * (len(LOG_COLUMNS) + len(get_kind(cfg.controller.kind).log_columns))
    per_value = 8 + (16 if "npz" in log_formats else 0) + (25 if "csv" in log_formats else 0)
    return float(runs * values * per_value)


def run_job(cfg: Config, out_dir: Path, compensation: str | None = None, fast: bool | None = None,
            make_driver: Callable[[Config, Inputs], Driver] | None = None, where: str | None = None,
            realtime: RealtimeOptions | None = None, log_formats: tuple[str, ...] = FORMATS,
            provenance: dict | Callable[[], dict] | None = None, inputs: Inputs | None = None) -> dict:  # fmt: skip
    """Run the ``servo run`` job into ``out_dir``; returns the summary (also written as
    ``summary.json``).  ``make_driver(cfg, inputs)``: a fresh driver per run instead of the
    simulated drive (``where`` describes it, e.g. the serial URL).  ``realtime``: pace
    every tick of the simulated drive on the wall clock (implies the tick path; asking for
    the fast path as well, or pacing a board, which is its own clock, is an error).
    ``compensation``: ``on``, ``off``, ``compare`` (both), or None: what ``[compensator]
    enabled`` says (:func:`~servo.runtime.controller.compensation_runs`).
    ``log_formats``: ``npz`` and/or ``csv``; ``provenance``
    (:func:`servo.io.provenance.provenance`, or a function that makes it, called after the
    runs) is recorded in the summary; ``inputs``: the
    run's inputs as :func:`prepare` built them (built here when None).  Memory does
    not grow with the run's length; the disk its logs need is checked first (one line if
    it is not there).  On a fault
    the drive is at zero current and the log of the interrupted run is kept."""
    check_realtime(realtime is not None, fast, make_driver is not None)
    if realtime is not None:
        realtime.check()
        fast = False
    fast = cfg.run.fast_path if fast is None else fast
    out_dir = Path(out_dir)
    labels = tuple("compensated" if on else "uncompensated" for on in compensation_runs(cfg, compensation))
    inputs = prepare(cfg, make_driver is None) if inputs is None else inputs  # before anything is written
    check_disk(out_dir, output_bytes(cfg, len(labels), log_formats), "the run logs",
               "shorten --duration, raise run.log_every, or write one format (--log-format npz)")  # fmt: skip
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write(out_dir / "config.toml", lambda p: Path(p).write_text(to_toml(cfg)))
    plot_logs, results, runs = {}, {}, {}
    for label in labels:
        progress.stage(f"{label} run", cfg.n_ticks, "ticks")
        figures, plot_logs[label], results[label] = run_simulated(cfg, out_dir, label == "compensated", fast,
                                                                  make_driver, realtime, log_formats, inputs)  # fmt: skip
        if not runs:
            age = process_age_s()
            startup = None if age is None else age - (time.perf_counter() - results[label].started)
        runs[label] = summarise(cfg, figures, results[label])
    progress.stage("plots")
    from servo.run import plots  # matplotlib: after the runs, not before the first tick
    from servo.run.page import page

    plots.plot_run(cfg, plot_logs, results, out_dir)
    if realtime is not None:
        plot_lateness(cfg, {k: r.lateness for k, r in results.items()}, out_dir / "lateness.png")
    path = "fast (all compiled)" if fast else "tick by tick through the driver interface"
    summary = {
        "ticks": cfg.n_ticks,
        "sample_rate_hz": cfg.run.sample_rate_hz,
        "duration_s": cfg.run.duration_s,
        "seed": cfg.run.seed,
        "path": path + (f" to {where}" if where else "") + (", paced in real time" if realtime else ""),
        "realtime": realtime is not None,
        "period_us": cfg.dt * 1e6,
        "startup_s": startup,
        "kernels_compiled": _cache.compiled_here(),
        "runs": runs,
        "provenance": or_default(provenance() if callable(provenance) else provenance, cfg),  # after the runs: git forks
        "files": sorted({p.name for p in out_dir.iterdir() if not p.name.startswith(".")} | {"summary.json", PAGE}),
    }
    write_json(out_dir / "summary.json", summary)
    page(summary, out_dir).write(out_dir)
    return summary


def format_summary(summary: dict, out_dir: Path) -> str:
    """The human summary ``servo run`` prints."""
    lines = [
        f"servo run: {summary['ticks']} ticks at {summary['sample_rate_hz'] / 1e3:g} kHz "
        f"({summary['duration_s']:g} s simulated), {summary['path']}",
    ]
    runs = summary["runs"]
    labels = list(runs)
    head = f"  {'tracking error RMS (nm)':<28}" + "".join(f"{lab:>16}" for lab in labels)
    lines.append(head)
    first = runs[labels[0]]
    for seg in first["error_rms_by_segment_m"]:
        lines.append(f"  {seg:<28}" + "".join(f"{runs[lab]['error_rms_by_segment_m'][seg] * 1e9:>16.1f}" for lab in labels))
    lines.append(f"  {'whole run':<28}" + "".join(f"{runs[lab]['error_rms_m'] * 1e9:>16.1f}" for lab in labels))
    for i, st in enumerate(first["steps"]):
        name = f"step {st['size_m'] * 1e6:+.2g} um ovsht%/settle"
        cells = "".join(_step_cells(runs[lab]["steps"][i]) for lab in labels)
        lines.append(f"  {name:<28}" + cells)
    if "pes_tracks" in first:  # the HDD benchmark's figures (docs/hdd.md)
        for key, name in (("sigma3", "PES 3 sigma"), ("rro_pp", "RRO peak-to-peak"), ("nrro_3sigma", "NRRO 3 sigma")):
            lines.append(f"  {name + ' (% track)':<28}" + "".join(f"{runs[lab]['pes_tracks'][key] * 100:>16.2f}" for lab in labels))
    for lab in labels:
        r = runs[lab]
        if "link" in r:  # the tick includes waiting for the board's sample: not a compute figure
            if "tick_us_median" in r:  # (none when the loop runs on the board)
                lines.append(f"  tick ({lab}, read to last task, incl. waiting for the board): {r['tick_us_median']:.1f} "
                             f"us median, {r['tick_us_p99']:.1f} us p99, {r['tick_us_max']:.0f} us max")  # fmt: skip
            lines.append(f"  link ({lab}): " + format_link(r["link"]))
        elif "tick_us_median" in r:
            lines.append(
                f"  compute ({lab}): {r['tick_us_median']:.2f} us/tick median, {r['tick_us_p99']:.2f} us p99, "
                f"{r['tick_us_max']:.0f} us max, first tick {r['tick_us_first']:.0f} us; "
                f"overruns of the {summary['period_us']:g} us period: {r['overruns']}"
            )
        else:
            lines.append(f"  compute ({lab}): {r['per_sample_us']:.3f} us/sample (controller + simulated drive, average)")
    if summary.get("startup_s") is not None:
        kernels = ("compiling the kernels: the first run after an install, an edit or a move" if summary.get("kernels_compiled")
                   else "cached kernels")  # fmt: skip
        lines.append(f"  startup: {summary['startup_s']:.2f} s from process start to the first tick "
                     f"(interpreter, imports, {kernels}, configure)")  # fmt: skip
    if summary.get("realtime"):
        g = runs[labels[0]]["realtime"]["granted"]
        lines.append(f"  realtime: {grant_line(g)}")
        lines += [f"  realtime: {note}" for note in g["notes"]]
        lines += [lateness_line(lab, runs[lab]["realtime"], summary["period_us"]) for lab in labels]
    lines.append(f"  wrote {out_dir}/: " + ", ".join(summary["files"]))
    return "\n".join(lines)


def format_link(link: dict) -> str:
    """One line about a serial link's run: frames, errors, the board's counters."""
    h, b = link["host"], link.get("board_stats") or {}
    errors = sum(v for k, v in h.items() if k not in ("rx_frames", "tx_frames", "rx_bytes", "tx_bytes", "ignored"))
    text = f"{h['rx_frames']} frames in, {h['tx_frames']} out, {errors} host-side errors"
    if b:
        text += (f"; board: {b.get('ticks', 0)} ticks, {b.get('missed_deadlines', 0)} missed deadlines, "
                 f"{b.get('faults', 0)} faults")  # fmt: skip
    return text


def _step_cells(st: dict) -> str:
    settle = "never" if st["settling_ms"] is None else f"{st['settling_ms']:.1f}ms"
    return f"{st['overshoot_pct']:>7.1f}%/{settle:>7}"

"""Plots of ``servo run``: tracking, normalised steps, currents, tick timing."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.io.plotting import finish, subplots
from servo.scenarios import segments

COL = {c: i for i, c in enumerate(LOG_COLUMNS)}
COLORS = {"compensated": "tab:blue", "uncompensated": "tab:orange"}


def plot_run(cfg: Config, logs: dict, results: dict | None = None, out_dir: Path | None = None) -> dict[str, Figure]:
    """The figures of a run, by file name: ``tracking.png``, ``steps.png``,
    ``current.png``, and ``timing.png`` when ``results`` (label -> loop result) have tick
    times (``timing``, :class:`~servo.runtime.durations.Durations`).  ``logs``: label
    (``compensated``/``uncompensated``) -> log array ``(ticks, len(LOG_COLUMNS))``.
    Each is written into ``out_dir`` when it is given."""
    out = None if out_dir is None else Path(out_dir)
    figs = {"tracking.png": _tracking(cfg, logs), "steps.png": _steps(cfg, logs), "current.png": _currents(logs)}
    ticks = {k: r.timing for k, r in (results or {}).items() if r.timing is not None}
    if ticks:
        figs["timing.png"] = _timing(cfg, ticks)
    return {name: finish(fig, None if out is None else out / name) for name, fig in figs.items()}


def _tracking(cfg, logs):
    fig, ax = subplots(2, 1, figsize=(10, 7), sharex=True)
    for label, a in logs.items():
        t, x0 = a[:, COL["t"]], a[0, COL["r"]]
        ax[0].plot(t, (a[:, COL["x"]] - x0) * 1e6, color=COLORS[label], lw=0.8, label=f"position, {label}")
        ax[1].plot(t, a[:, COL["e"]] * 1e6, color=COLORS[label], lw=0.8, label=label)
    ax[0].plot(t, (a[:, COL["r"]] - x0) * 1e6, "k--", lw=0.8, label="reference")
    for t0 in list(cfg.scenario.step_times) + [cfg.scenario.disturbance_start]:
        for x in ax:
            x.axvline(t0, color="0.8", lw=0.6, zorder=0)
    ax[0].set_ylabel("position from hold (um)")
    ax[1].set_ylabel("tracking error r - x (um)")
    ax[1].set_xlabel("time (s)")
    ax[0].set_title(f"Closed loop on the simulated drive: hold, steps, {cfg.scenario.disturbance_amplitude * 1e3:g} mA "
                    f"{cfg.scenario.disturbance_hz:g} Hz disturbance from {cfg.scenario.disturbance_start:g} s")  # fmt: skip
    for x in ax:
        x.grid(alpha=0.3)
        x.legend(fontsize=8, loc="upper left")
    return fig


def _steps(cfg, logs):
    """Each step normalised by its size: a linear plant gives the same curve at every size."""
    fig, axes = subplots(1, len(logs), figsize=(5.5 * len(logs), 4.2), sharey=True, squeeze=False)
    steps = cfg.scenario.kind == "steps"  # the HDD benchmark's scenario has none
    times, pos = (cfg.scenario.step_times, cfg.scenario.step_positions) if steps else ((), ())
    ends = {name: b for name, _, b in segments(cfg)}
    for ax, (label, a) in zip(axes[0], logs.items()):
        t, x, x0 = a[:, COL["t"]], a[:, COL["x"]], a[0, COL["r"]]
        prev = 0.0
        for i, (ts, p) in enumerate(zip(times, pos)):
            if p != prev and ts < cfg.run.duration_s:
                te = ends[f"step {i + 1}"]
                m = (t >= ts) & (t < te)
                ax.plot((t[m] - ts) * 1e3, (x[m] - x0 - prev) / (p - prev), lw=1,
                        label=f"{(p - prev) * 1e6:+.3g} um at {ts:g} s")  # fmt: skip
            prev = p
        ax.axhline(1.0, color="k", lw=0.6)
        ax.axhspan(0.95, 1.05, color="0.9", zorder=0)
        ax.set_title(label)
        ax.set_xlabel("time after the step (ms)")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # a run shorter than the first step has none
            ax.legend(fontsize=8, loc="lower right")
        else:
            ax.text(0.5, 0.5, "no step within the run", transform=ax.transAxes, ha="center", color="0.4")
    axes[0][0].set_ylabel("position change / step size")
    fig.suptitle("Normalised step responses (the band is +-5 %)")
    return fig


def _currents(logs):
    fig, ax = subplots(3, 1, figsize=(10, 8), sharex=True)
    for label, a in logs.items():
        t = a[:, COL["t"]]
        ax[0].plot(t, a[:, COL["u"]] * 1e3, color=COLORS[label], lw=0.8, label=f"u, {label}")
    if "compensated" in logs:
        a = logs["compensated"]
        t = a[:, COL["t"]]
        ax[0].plot(t, a[:, COL["u_c"]] * 1e3, color="tab:green", lw=0.8, label="u_c (compensation)")
        ax[1].plot(t, a[:, COL["h_hat"]] * 1e3, color="tab:purple", lw=0.8, label="Dahl estimate H_hat")
        ax[2].step(t, a[:, COL["regime"]], color="tab:red", lw=0.8, where="post", label="regime (0 Dahl, 1 eq. 3)")
    ax[0].set_ylabel("current (mA)")
    ax[1].set_ylabel("H_hat (mA)")
    ax[2].set_ylabel("regime")
    ax[2].set_xlabel("time (s)")
    for x in ax:
        x.grid(alpha=0.3)
        if x.get_legend_handles_labels()[0]:
            x.legend(fontsize=8, loc="upper left")
    return fig


def _timing(cfg, ticks):
    fig, ax = subplots(figsize=(8, 4))
    period = cfg.dt * 1e6
    for label, durations in ticks.items():
        edges_ns, counts = durations.histogram()
        us = edges_ns / 1e3
        bins = np.logspace(np.log10(max(us.min(), 0.1)), np.log10(max(durations.max / 1e3, period) * 1.1), 80)
        ax.hist(np.maximum(us, bins[0]), bins=bins, weights=counts, histtype="step", color=COLORS[label], label=label)
    ax.axvline(period, color="r", lw=1, label=f"period {period:g} us")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("compute time per tick (us): read + controller + write + tasks")
    ax.set_ylabel("ticks")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig

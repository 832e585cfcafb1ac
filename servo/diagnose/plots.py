"""Figures of a diagnosis: the residual over time with the located windows, against the
state, its spectrum, and the fits before and after on the held-out part.  Each returns
its Figure and writes it as PNG only when given a path.

A figure draws a bounded number of points whatever the recording's length (a PNG is
about a thousand pixels wide): a time series longer than :data:`ENVELOPE_BUCKETS`
buckets is drawn as its minimum-maximum envelope per bucket (:func:`envelope`), the
same picture at that width; a scatter draws every k-th of its points, at most
:data:`MAX_SCATTER` (its bin means are computed on all of them).  Drawing every row of
a 1e6-sample recording took 26 s of 44 at load 10, and grew with the recording.  Each
figure has fixed margins and is written as laid out, drawn once: cropping it to what is
drawn (``bbox_inches="tight"``) drew each twice, a third of the five figures' 2.2 s."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from servo import physics
from servo.diagnose.job import Diagnosis
from servo.io.plotting import finish, subplots


#: a time series with more samples than twice this is drawn as its envelope over this many buckets
ENVELOPE_BUCKETS = 2000
#: most points a scatter of the residual against the state draws per series
MAX_SCATTER = 20_000


def envelope(t: np.ndarray, y: np.ndarray, buckets: int = ENVELOPE_BUCKETS) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` ((n,) each) as at most ``2*buckets`` points: each bucket of consecutive
    samples as its minimum and its maximum (NaN ignored; NaN where the whole bucket is,
    a gap in the line), at the bucket's first time.  A line through them covers what
    the line through every sample covers, at a bucket's resolution."""
    n = y.size
    if n <= 2 * buckets:
        return t, y
    start = np.linspace(0, n, buckets + 1).astype(int)[:-1]
    lo, hi = np.fmin.reduceat(y, start), np.fmax.reduceat(y, start)
    return np.repeat(t[start], 2), np.column_stack([lo, hi]).ravel()


def _scale(fu: str):
    return (1e3, "m" + fu) if fu == "A" else (1.0, fu)


def _title(D: Diagnosis) -> str:
    names = ", ".join(f.physics for f in D.findings) or "no finding"
    return f"{Path(D.rec.source).name or D.rec.source}: {names}"


def plot_time(D: Diagnosis, path: Path | None = None) -> Figure:
    """Force residual over the whole record, before and after, with the flagged windows;
    only the part after the split is marked "held out" (the training part is not)."""
    sig, (k, unit) = D.sig, _scale(D.opt.force_unit)
    t, v = sig.t_rows, sig.valid
    fig, ax = subplots(2, 1, figsize=(11, 7), sharex=True)
    rb = np.where(v, D.residual_before, np.nan) * k
    ra = np.where(v, D.residual_after, np.nan) * k
    ax[0].plot(*envelope(t, rb), color="tab:red", lw=0.6, label="baseline")
    ax[0].plot(*envelope(t, ra), color="k", lw=0.6, alpha=0.8, label="final model")
    for t0, t1 in D.locate["time"]["flagged"]:
        for a in ax:
            a.axvspan(t0, t1, color="gold", alpha=0.3, lw=0)
    t_split = t[np.flatnonzero(D.design.train_rows)[-1]]
    for a in ax:
        a.axvline(t_split, color="tab:blue", ls="--", lw=1)
    ax[0].axvspan(t_split, t[-1], color="tab:blue", alpha=0.06, lw=0, label="held out (nothing fitted or chosen on it)")
    ax[0].text(t_split, np.nanmax(rb) if np.isfinite(np.nanmax(rb)) else 0, "  held out", color="tab:blue", va="top")
    w = D.locate["time"]["windows"]
    mid = [0.5 * (x["t0"] + x["t1"]) for x in w]
    ax[1].step(mid, [x["rms"] * k if x["rms"] is not None else np.nan for x in w], where="mid", color="tab:red",
               label="baseline residual RMS per window")  # fmt: skip
    ax[1].axhline(D.locate["time"]["noise_rms"] * k, color="gray", ls=":", label="median window")
    ax[0].set_ylabel(f"force residual ({unit})")
    ax[1].set_ylabel(f"RMS ({unit})")
    ax[1].set_xlabel("time (s)")
    ax[0].set_title(f"{_title(D)}\nresidual over time; shaded: windows whose power stands out from the others "
                    f"(family-wise false alarm {100 * D.opt.alpha:.0f} %)")  # fmt: skip
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=8, loc="upper left")
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.9, hspace=0.15)  # fixed: drawn once
    return finish(fig, path, tight=False)


def plot_state(D: Diagnosis, path: Path | None = None) -> Figure:
    """Residual against position, velocity, direction and distance since reversal,
    with bin means before (red) and after (black)."""
    k, unit = _scale(D.opt.force_unit)
    v = D.sig.valid
    fig, axes = subplots(2, 2, figsize=(11, 8))
    st = D.locate["state"]["variables"]
    for ax, (name, (vals, sign, u)) in zip(axes.ravel(), D.state.items()):
        rb = (D.residual_before * (sign if sign is not None else 1.0))[v] * k
        ra = (D.residual_after * (sign if sign is not None else 1.0))[v] * k
        x = vals[v]
        if name == "distance_since_reversal":
            x = np.maximum(x, 1e-12)
            ax.set_xscale("log")
        every = slice(None, None, max(1, -(-x.size // MAX_SCATTER)))
        ax.plot(x[every], rb[every], ".", ms=1.5, color="tab:red", alpha=0.25, rasterized=True)
        ax.plot(x[every], ra[every], ".", ms=1.5, color="k", alpha=0.15, rasterized=True)
        info = st[name]
        red, black, xv = [], [], vals[v]  # the bins' means as two collections of segments, not a line each
        for b in info["bins"]:
            lo, hi = b["lo"], b["hi"]
            if name == "distance_since_reversal":
                lo = max(lo, 1e-12)
            sel = (xv >= b["lo"]) & (xv <= b["hi"])
            red.append((lo, hi, b["mean"] * k, 2.5 if b["flagged"] else 1.2))
            if sel.any():
                black.append((lo, hi, ra[sel].mean()))
        if red:
            lo, hi, y, lw = np.array(red).T
            ax.hlines(y, lo, hi, color="tab:red", lw=lw, capstyle="projecting")
        if black:
            lo, hi, y = np.array(black).T
            ax.hlines(y, lo, hi, color="k", lw=1.2, capstyle="projecting")
        lab = "residual x direction" if sign is not None else "residual"
        ax.set_xlabel(f"{name.replace('_', ' ')} ({u})")
        ax.set_ylabel(f"{lab} ({unit})")
        ax.set_title(f"{name.replace('_', ' ')}: p = {info['p']:.2g}" + (" (structured)" if info["flagged"] else ""),
                     fontsize=9)  # fmt: skip
        ax.grid(alpha=0.3)
        lo, hi = np.percentile(np.concatenate([rb, ra]), [0.5, 99.5])
        pad = 0.2 * (hi - lo)
        ax.set_ylim(lo - pad, hi + pad)
    fig.suptitle(f"{_title(D)}\nheld-out residual vs state: baseline (red, bin means thick where flagged), "
                 "final model (black)", fontsize=10)  # fmt: skip
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.07, top=0.9, hspace=0.32, wspace=0.22)  # fixed: no layout pass
    return finish(fig, path, tight=False)


def plot_spectrum(D: Diagnosis, path: Path | None = None) -> Figure:
    """Residual spectra before/after with the peak threshold, and the coherence of the
    baseline residual with the input."""
    from servo.frf.estimate import psd

    k, unit = _scale(D.opt.force_unit)
    sp, co = D.locate["spectrum"], D.locate["coherence"]
    fs = 1.0 / D.sig.row_dt
    f, Pa = psd(np.where(D.sig.valid, D.residual_after, 0.0) * k, fs, 2 * (sp["f_hz"].size - 1))
    fig, ax = subplots(2, 1, figsize=(11, 7), sharex=True)
    ax[0].loglog(sp["f_hz"][1:], sp["psd"][1:] * k * k, color="tab:red", label="baseline residual")
    ax[0].loglog(f[1:], Pa[1:], color="k", label="final model residual")
    ax[0].loglog(sp["f_hz"][1:], sp["floor"][1:] * sp["threshold_ratio"] * k * k, color="gray", ls=":",
                 label="peak threshold (family-wise 5 %)")  # fmt: skip
    ax[0].set_ylabel(f"PSD ({unit}^2/Hz)")
    ax[0].legend(fontsize=8)
    ax[1].semilogx(co["f_hz"][1:], co["coherence"][1:], color="tab:red", label="baseline residual vs input")
    ax[1].axhline(co["threshold"], color="gray", ls=":", label="independence threshold (closed loop: see docs)")
    ax[1].set_ylabel("coherence")
    ax[1].set_xlabel("frequency (Hz)")
    ax[1].set_ylim(0, 1)
    ax[1].legend(fontsize=8)
    ax[0].set_title(f"{_title(D)}\nresidual spectrum and residual-input coherence")
    for a in ax:
        a.grid(alpha=0.3, which="both")
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.9, hspace=0.15)  # fixed: drawn once
    return finish(fig, path, tight=False)


def plot_fits(D: Diagnosis, path: Path | None = None) -> Figure:
    """On the held-out part: force, baseline and final fits (a zoom), and the
    short-horizon simulated output error before and after."""
    k, unit = _scale(D.opt.force_unit)
    sig = D.sig
    test = np.flatnonzero(~D.design.train_rows)
    n = test.size
    z = test[n // 2 - min(n // 2, 150) : n // 2 + min(n // 2, 150)]
    y = D.baseline_fit.y + 0.0
    fig, ax = subplots(3, 1, figsize=(11, 9))
    t = sig.t_rows
    ax[0].plot(t[z], y[z] * k, color="tab:blue", lw=1.5, label="recorded force (rows)")
    ax[0].plot(t[z], (y - D.baseline_fit.residual)[z] * k, color="tab:red", lw=1, ls="--", label="baseline")
    ax[0].plot(t[z], (D.final_fit.y - D.final_fit.residual)[z] * k, color="k", lw=1, ls=":", label="final model")
    ax[0].set_ylabel(f"force ({unit})")
    vz = sig.valid[z]
    ax[1].plot(t[z], np.where(vz, D.baseline_fit.residual[z], np.nan) * k, color="tab:red", lw=0.8, label="baseline")
    ax[1].plot(t[z], np.where(vz, D.final_fit.residual[z], np.nan) * k, color="k", lw=0.8, label="final model")
    ax[1].set_ylabel(f"residual ({unit})")
    e = D.errors
    lattice = physics.diagnosed_by("lattice")  # the term the sensor's lattice test names
    moved = any(f.physics == lattice and f.after.get("rows_differ") for f in D.findings)
    rows = " (quantisation-aware rows; the force error before is on the default rows)" if moved else ""
    ax[0].set_title(f"{_title(D)}\nheld-out part: force error {e['test_force_rel_pct']['before']:.3g} % -> "
                    f"{e['test_force_rel_pct']['after']:.3g} %{rows}")  # fmt: skip
    if D.pred_before is not None:
        before = "baseline (default path)" if moved else "baseline"
        for pred, col, lab in ((D.pred_before, "tab:red", before), (D.pred_after, "k", "final model")):
            eb, _ = pred.sse()
            rms = np.sqrt(eb / pred.pred.shape[1])
            ax[2].semilogy(sig.t[pred.starts], np.maximum(rms, 1e-15), color=col, lw=0.8, label=lab)
        _, dref = D.pred_before.sse()
        ax[2].semilogy(sig.t[D.pred_before.starts], np.sqrt(dref / D.pred_before.pred.shape[1]), color="gray", lw=0.6,
                       ls=":", label="motion beyond coasting")  # fmt: skip
        ax[2].set_title(f"simulated output, {1e3 * e['horizon_s']:.3g} ms ahead from measured states: NRMSE "
                        f"{e['test_output_nrmse']['before']:.3g} -> {e['test_output_nrmse']['after']:.3g}", fontsize=9)  # fmt: skip
        ax[2].set_ylabel(f"RMS position error ({D.opt.position_unit})")
    else:
        ax[2].text(0.5, 0.5, D.simulate_note, ha="center", transform=ax[2].transAxes)
    ax[2].set_xlabel("time (s)")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=8, loc="upper right")
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.06, top=0.92, hspace=0.3)  # fixed: no layout pass
    return finish(fig, path, tight=False)


def plot_frf(D: Diagnosis, path: Path | None = None) -> Figure | None:
    """The frequency evidence (the frequency-domain path, over the whole band with
    excitation): the measured response of the training and test parts against the
    model's without and with the modes it found, the bins the test used, the
    departures it located (shaded) and the rows' band edge, and the coherence; None
    when that path did not compare."""
    r = D.frf
    if r is None or not r.ran:
        return None
    lo, hi = r.band_hz
    fig, ax = subplots(2, 1, figsize=(11, 7), sharex=True)
    for resp, color, name in ((r.train, "0.6", "training part"), (r.test, "tab:blue", "test part")):
        sel = (resp.f > 0.5 * lo) & (resp.f <= hi)
        ax[0].loglog(resp.f[sel], np.abs(resp.H[sel]), color=color, lw=0.8, label=f"H1, {name}")
        ax[1].semilogx(resp.f[sel], resp.coh[sel], color=color, lw=0.8, label=name)
    te = r.test
    sel = (te.f > 0.5 * lo) & (te.f <= hi)
    ax[0].loglog(te.f[sel], np.abs(r.model_before[sel]), color="tab:red", label="model before")
    if r.modes:
        ax[0].loglog(te.f[sel], np.abs(r.model_after[sel]), color="k", ls="--", label="model with the modes found")
    use = r.usable_test & sel
    ax[0].plot(te.f[use], np.abs(te.H[use]), ".", color="tab:green", ms=4, zorder=3, label="test bins used")
    deps = (r.before or {}).get("departures") or []
    for a in ax:
        if r.rows_edge_hz:
            a.axvline(r.rows_edge_hz, color="0.5", ls=":", label="rows' band edge" if a is ax[0] else None)
        for k, d in enumerate(deps):
            a.axvspan(d["band_hz"][0], d["band_hz"][1], color="tab:orange", alpha=0.25,
                      label="departs (test part, model before)" if a is ax[0] and k == 0 else None)  # fmt: skip
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=8)
    ax[0].set_ylabel(f"|x/u| (m/{D.opt.force_unit})")
    ax[1].set_ylabel("coherence")
    ax[1].set_ylim(0, 1)
    ax[1].set_xlabel("frequency (Hz)")
    ax[0].set_title(f"{_title(D)}\nthe frequency response at full rate ({lo:.4g}-{hi:.4g} Hz) against the model's")
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.9, hspace=0.15)  # fixed: drawn once
    return finish(fig, path, tight=False)


#: each figure's file, its function and its relative cost (tenths of a second of CPU at 1e6
#: samples, each drawn once, 2026-11-28: the state figure's four panels draw the most), in
#: the order of the report's files
FIGURES = (("residual_time.png", "plot_time", 2.0), ("residual_state.png", "plot_state", 5.3),
           ("residual_spectrum.png", "plot_spectrum", 2.3), ("fits.png", "plot_fits", 2.9),
           ("frf.png", "plot_frf", 2.8))  # fmt: skip


def figure_files(D: Diagnosis) -> list:
    """The file names :func:`write_plots` writes for ``D``: the four of every diagnosis,
    and ``frf.png`` when the frequency-domain path compared."""
    ran = D.frf is not None and D.frf.ran
    return [name for name, fn, _ in FIGURES if fn != "plot_frf" or ran]


def _draw(D: Diagnosis, out: Path, names) -> None:
    for name, fn, _ in FIGURES:
        if name in names:
            globals()[fn](D, out / name)


def _share(names) -> tuple[list, list]:
    """``names`` split in two by cost, each largest first to the lighter side: (the other
    process's, this one's)."""
    cost = {name: c for name, _, c in FIGURES}
    a, b, ca, cb = [], [], 0.0, 0.0
    for name in sorted(names, key=lambda n: -cost[n]):
        if ca <= cb:
            a.append(name)
            ca += cost[name]
        else:
            b.append(name)
            cb += cost[name]
    return a, b


def _forkable() -> bool:
    """Whether this process may fork a drawing process: a POSIX ``fork`` start method, and
    not a daemonic process (a Dask worker's, which may have no children)."""
    import multiprocessing as mp

    return "fork" in mp.get_all_start_methods() and not mp.current_process().daemon


def _child(D: Diagnosis, out: Path, names) -> None:
    """The forked process's work: its figures, each written atomically; a failure is its
    exit status only (the parent draws what is missing, and raises as a serial run would)."""
    import os

    try:
        _draw(D, out, names)
    except BaseException:  # noqa: BLE001 - reported by the exit status, redrawn by the parent
        os._exit(1)


class PlotWriter:
    """The figures of a diagnosis being written into ``out`` while the caller does
    something else (writes the report); :meth:`finish` returns their file names once all
    are written.

    Matplotlib draws holding the interpreter lock and is not thread-safe, so the second
    core is used by a forked process: it inherits the diagnosis (nothing is pickled) and
    draws about half of the figures (by cost, :data:`FIGURES`), each written atomically;
    this process draws the rest in :meth:`finish`, waits for the other, and draws itself
    any figure the other did not write (an error is then raised here, as in a serial
    run).  Where a process cannot fork (no ``fork`` start method, a daemonic process) or
    ``parallel`` is False, :meth:`finish` draws them all.  Each figure is its own
    :class:`~matplotlib.figure.Figure` on the Agg canvas, outside ``pyplot``: nothing
    global changes in either process."""

    def __init__(self, D: Diagnosis, out: Path, parallel: bool = True):
        self.D, self.out, self.names = D, Path(out), figure_files(D)
        self.proc, self.mine = None, list(self.names)
        if parallel and len(self.names) > 1 and _forkable():
            import multiprocessing as mp
            import sys

            from matplotlib.backends import backend_agg  # noqa: F401 - imported once, before the fork

            theirs, mine = _share(self.names)
            for n in theirs:  # a figure the other process does not write is drawn here: none left from before
                (self.out / n).unlink(missing_ok=True)
            for stream in (sys.stdout, sys.stderr):  # nothing buffered is written twice
                stream.flush()
            try:
                proc = mp.get_context("fork").Process(target=_child, args=(D, self.out, theirs), daemon=True)
                proc.start()
            except OSError:  # no process to spare: all of them drawn here
                return
            self.proc, self.mine = proc, mine

    def abandon(self) -> None:
        """Stop the other process, if any, and wait for it (the caller failed: its folder
        goes)."""
        if self.proc is not None:
            self.proc.terminate()
            self.proc.join()
            self.proc = None

    def finish(self) -> list:
        """Draw this process's figures, wait for the other's, draw any it did not write;
        returns the file names written."""
        _draw(self.D, self.out, self.mine)
        if self.proc is not None:
            self.proc.join()
            self.proc = None
            _draw(self.D, self.out, [n for n in self.names if n not in self.mine and not (self.out / n).is_file()])
        return list(self.names)


def write_plots(D: Diagnosis, out: Path, parallel: bool = True) -> list:
    """Write the figures into ``out`` (the four of every diagnosis, and ``frf.png`` when
    the frequency-domain path compared), on two processes unless ``parallel`` is False
    (:class:`PlotWriter`); returns their file names."""
    return PlotWriter(D, out, parallel).finish()


__all__ = ["FIGURES", "PlotWriter", "envelope", "figure_files", "plot_fits", "plot_frf", "plot_spectrum", "plot_state",
           "plot_time", "write_plots"]

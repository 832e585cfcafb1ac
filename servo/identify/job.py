"""The ``servo identify`` job: identify, write the outputs into one folder, summarise.

Writes ``summary.json`` (estimates, std devs, conditioning, relative error, settings,
and for a simulated experiment the drive's values), ``params_<path>.csv``, the rows of
each fit ``rows_<path>.csv`` (t, y, y_hat, residual, measured and estimated
acceleration), and per path ``acceleration_<path>.png`` (paper Fig. 5) and
``force_fit_<path>.png``.
"""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from servo.identify.identification import Identification, identify
from servo.identify.plots import estimated_acceleration, plot_acceleration, plot_force_fit
from servo.identify.regressors import RobustSettings, units
from servo.io.atomic import atomic_write, write_json
from servo.io.provenance import or_default
from servo.io.recording import Recording
from servo.io.runlog import write_csv


def write_identification(ident: Identification, out: Path, force_unit: str = "A", title: str = "",
                         position_unit: str = "m") -> list[str]:  # fmt: skip
    """Write the CSVs and PNGs of one fit into ``out``; returns the file names."""
    reg, fit, p = ident.regression, ident.fit, ident.regression.path
    cols = ["t", "y", "y_hat", "residual", "x", "v", "a"]
    data = [reg.t, reg.y, fit.y_hat, fit.residual, reg.x, reg.v, reg.a]
    if "J" in reg.terms:
        cols += ["a_regressor", "a_estimated"]
        data += [reg.column("J"), estimated_acceleration(ident)]
    write_csv(out / f"rows_{p}.csv", cols, np.column_stack(data))
    u = units(force_unit, position_unit)
    lines = ["term,estimate,std,rel_std_pct,unit"] + [
        f"{t},{v:.10g},{s:.6g},{r:.4g},{u[t]}" for t, v, s, r in zip(fit.terms, fit.params, fit.std, fit.rel_std_pct)
    ]
    atomic_write(out / f"params_{p}.csv", lambda f: Path(f).write_text("\n".join(lines) + "\n"))
    names = [f"rows_{p}.csv", f"params_{p}.csv"]
    plot_force_fit(ident, out / f"force_fit_{p}.png", force_unit, title=title and f"{title}: force fit ({p} path), "
                   f"relative error {fit.rel_error_pct:.3g} %")  # fmt: skip
    names.append(f"force_fit_{p}.png")
    if "J" in reg.terms:
        plot_acceleration(ident, out / f"acceleration_{p}.png", position_unit=position_unit)
        names.append(f"acceleration_{p}.png")
    return names


def run_identify(rec: Recording, out: Path, paths, terms, settings: RobustSettings, force_unit: str = "A",
                 reference: dict | None = None, force_lag_s: float | dict = 0.0, provenance: dict | None = None,
                 position_unit: str = "m") -> dict:  # fmt: skip
    """Identify ``rec`` with each of ``paths`` and write everything into ``out``.

    ``reference``: named sets of known parameter values to compare with (for a simulated
    experiment: the drive's nominal values and what model (3) can represent); a set may
    be given per path (``{"robust": {...}, "paper": {...}}``).  ``force_lag_s``: seconds,
    or a dict per path.  ``provenance``: recorded in the summary as given
    (:func:`servo.io.provenance.provenance`).  ``force_unit``, ``position_unit``: the
    recording's (a rotary axis: ``N*m`` or ``A``, and ``rad``), for every unit written."""
    out = Path(out)
    lag = force_lag_s if isinstance(force_lag_s, dict) else {p: force_lag_s for p in paths}
    results = {p: identify(rec, p, terms, settings, lag[p]) for p in paths}  # all fits before any file
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for ident in results.values():
        files += write_identification(ident, out, force_unit, position_unit=position_unit)
    summary = {
        "recording": rec.source,
        "samples": rec.n,
        "sample_rate_hz": rec.sample_rate_hz,
        "force_unit": force_unit,
        "position_unit": position_unit,
        "fits": {p: r.as_dict(force_unit, position_unit) for p, r in results.items()},
    }
    if reference:
        summary["reference"] = reference
        for p, r in results.items():
            refs = {name: ref.get(p, ref) for name, ref in reference.items()}
            summary["fits"][p]["reference"] = refs
            summary["fits"][p]["error_pct"] = {
                name: {t: 100 * (r.fit[t] - ref[t]) / abs(ref[t]) for t in r.fit.terms if ref.get(t)}
                for name, ref in refs.items()
            }
    summary["provenance"] = or_default(provenance)
    summary["files"] = sorted(files + ["summary.json"])
    write_json(out / "summary.json", summary)
    return summary


#: why the paper's path is far off on a simulated drive with flexible modes (docs/identification.md)
PAPER_PATH_NOTE = (
    "why the paper path is so far off here: it differentiates the measured velocity, which carries the drive's "
    "flexible modes (rung by every square-wave edge); their backward-difference acceleration is regressor noise "
    "correlated with the input, and the least squares push it into the terms, most into the weakly excited K "
    "(K*x is ~1 % of the force: hence errors of thousands of percent). On the drive without modes this path is "
    "within 1 % of model (3) (docs/identification.md); on a drive with resonances use the robust path."
)


def paper_path_note(summary: dict, has_modes: bool, limit_pct: float = 20.0) -> str | None:
    """:data:`PAPER_PATH_NOTE` when the summary's paper path misses what model (3) can
    represent of a simulated drive that has flexible modes by more than ``limit_pct``
    in some term; else None."""
    fit = summary["fits"].get("paper")
    if fit is None or not has_modes:
        return None
    err = fit.get("error_pct", {}).get("model (3) of the drive", {})
    return PAPER_PATH_NOTE if err and max(abs(e) for e in err.values()) > limit_pct else None


def format_summary(summary: dict, out: Path) -> str:
    """The human summary ``servo identify`` prints."""
    lines = [f"servo identify: {summary['recording']} ({summary['samples']} samples at {summary['sample_rate_hz']:.6g} Hz)"]
    for path, fit in summary["fits"].items():
        ref = fit.get("reference", {})
        s = fit["settings"]
        how = ("measured velocity, backward-difference acceleration" if path == "paper" else
               f"Butterworth {s['butter_order']} at {s['cutoff_hz']:.4g} Hz, central differences, "
               f"parallel decimation by {s['decimate']}")  # fmt: skip
        if s.get("force_lag_s"):
            how += f"; force lag {s['force_lag_s'] * 1e6:.3g} us"
        lines.append(f"  {path} path ({how}): {fit['n_rows']} rows")
        head = f"    {'term':<4} {'estimate':>13} {'std':>10} {'std %':>7}  unit"
        for name in ref:
            head += f"  {'vs ' + name:>18}"
        lines.append(head)
        for t in fit["terms"]:
            row = (f"    {t:<4} {fit['params'][t]:>13.6g} {fit['std'][t]:>10.3g} {fit['rel_std_pct'][t]:>7.3g}"
                   f"  {fit['units'][t]:<8}")  # fmt: skip
            for name, vals in ref.items():
                e = fit.get("error_pct", {}).get(name, {}).get(t)
                row += f"  {vals[t]:>9.4g} ({e:+6.1f}%)" if e is not None else f"  {vals[t]:>9.4g} {'':>9}"
            lines.append(row)
        lines.append(f"    relative error {fit['rel_error_pct']:.4f} %, condition number {fit['cond']:.4g} "
                     f"(column-scaled {fit['cond_scaled']:.3g})")  # fmt: skip
        note = summary.get("notes", {}).get(path)
        if note:
            lines += textwrap.wrap(note, 110, initial_indent="    ", subsequent_indent="      ")
    lines.append(f"  wrote {out}/: " + ", ".join(summary["files"]))
    return "\n".join(lines)


__all__ = ["PAPER_PATH_NOTE", "format_summary", "paper_path_note", "run_identify", "write_identification"]

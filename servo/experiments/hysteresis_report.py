"""The ``servo hysteresis`` job: Dahl fit of a current-vs-position loop (Fig. 3) and the
average slope of a large loop (Fig. 4), from a recording or the simulated drive.

Outputs in one folder: ``summary.json``, ``dahl_fit.csv`` (t, x, v, u, u_hat, H),
``hysteresis_loop.png``, and for the simulated drive also ``recording_small.csv``,
``recording_large.csv`` and ``hysteresis_large.png``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from servo.config import Config
from servo.experiments.hysteresis import HysteresisExperiment, average_slope, run_large_loop, run_small_loop
from servo.experiments.hysteresis_plots import plot_large_loop, plot_small_loop
from servo.identify.dahl_fit import DahlFit, fit_dahl
from servo.identify.regressors import IdentificationError
from servo.io.atomic import write_json
from servo.io.provenance import or_default
from servo.io.recording import Recording, save_recording_csv
from servo.io.runlog import write_csv


def _write_fit(out: Path, t, x, v, u, fit: DahlFit) -> None:
    write_csv(out / "dahl_fit.csv", ["t", "x", "v", "u", "u_hat", "H"], np.column_stack([t, x, v, u, fit.u_hat, fit.H]))


def run_hysteresis_recording(rec: Recording, out: Path, deadband: float, fit_alpha: bool, alpha: float,
                             slope: bool, provenance: dict | None = None) -> dict:  # fmt: skip
    """Fit the Dahl model to the whole recording (and, if ``slope``, the average slope);
    ``provenance`` goes into the summary as given."""
    if rec.v is None:
        raise IdentificationError("the Dahl fit needs the velocity direction: map a velocity column with --columns v=NAME")
    if not (np.isfinite(deadband) and deadband >= 0.0):
        raise IdentificationError(f"the direction deadband must be a speed >= 0 m/s, got {deadband:g}")
    fit = fit_dahl(rec.x, rec.v, rec.u, deadband=deadband, fit_alpha=fit_alpha, alpha=alpha)
    problems = fit.problems()
    if problems:  # nothing written: a result that cannot be trusted is not reported as one
        raise IdentificationError(f"hysteresis: the Dahl fit cannot be trusted: {'; '.join(problems)}. Does the "
                                  "recording hold back-and-forth motion within the pivot's pre-sliding range?")  # fmt: skip
    avg = average_slope(rec.t, rec.x, rec.v, rec.u, rec.dt) if slope else None
    out.mkdir(parents=True, exist_ok=True)
    _write_fit(out, rec.t, rec.x, rec.v, rec.u, fit)
    plot_small_loop(rec.t, rec.x, rec.u, fit, out / "hysteresis_loop.png")
    summary = {"recording": rec.source, "samples": rec.n, "dahl": fit.as_dict()}
    files = ["dahl_fit.csv", "hysteresis_loop.png"]
    if avg is not None:
        summary["average_slope"] = avg.as_dict()
        plot_large_loop(rec.x, rec.u, avg, out / "hysteresis_large.png", title="Current vs position and its average slope")
        files.append("hysteresis_large.png")
    return _finish(out, summary, files, provenance)


def run_hysteresis_simulated(cfg: Config, out: Path, exp: HysteresisExperiment, fit_alpha: bool = True,
                             provenance: dict | None = None) -> dict:  # fmt: skip
    """The small-loop and large-loop experiments on the simulated drive, with the fit;
    ``provenance`` goes into the summary as given."""
    small = run_small_loop(cfg, exp)
    fit = fit_dahl(small["x"], small["v"], small["u"], deadband=cfg.controller.direction_deadband, fit_alpha=fit_alpha)
    large = run_large_loop(cfg, exp)
    avg = average_slope(large["t"], large["x"], large["v"], large["u"], cfg.dt)
    out.mkdir(parents=True, exist_ok=True)
    for name, log in (("small", small), ("large", large)):
        save_recording_csv(out / f"recording_{name}.csv", Recording(log["t"], log["u"], log["x"], log["v"]))
    _write_fit(out, small["t"], small["x"], small["v"], small["u"], fit)
    plot_small_loop(small["t"], small["x"], small["u"], fit, out / "hysteresis_loop.png",
                    title=f"Hysteresis loop, {exp.amplitude * 1e3:g} mA AM sine at {exp.hz:g} Hz: experiment vs Dahl fit")  # fmt: skip
    plot_large_loop(large["x"], large["u"], avg, out / "hysteresis_large.png",
                    title=f"Large range (+-{exp.large_amplitude_m * 1e3:g} mm triangle at {exp.large_hz:g} Hz): "
                    "average slope = bearing stiffness (eq. 11)")  # fmt: skip
    d = cfg.drive
    drive = {"sigma": d.sigma, "Ha": d.Ha, "alpha": d.alpha, "c": d.h0, "K": d.K}
    summary = {
        "recording": "simulated drive",
        "experiment": exp.__dict__,
        "small_loop": {"x_range_m": float(np.ptp(small["x"])), "u_range_A": float(np.ptp(small["u"]))},
        "dahl": fit.as_dict(),
        "average_slope": avg.as_dict(),
        "drive": drive,
        "error_pct": {
            **{k: 100 * (fit.params[k] - drive[k]) / abs(drive[k]) for k in ("sigma", "Ha", "alpha", "c")},
            "K": 100 * (avg["K"] - d.K) / abs(d.K),
        },
    }
    files = ["recording_small.csv", "recording_large.csv", "dahl_fit.csv", "hysteresis_loop.png", "hysteresis_large.png"]
    return _finish(out, summary, files, provenance)


def _finish(out: Path, summary: dict, files: list[str], provenance: dict | None = None) -> dict:
    summary["provenance"] = or_default(provenance)
    summary["files"] = sorted(files + ["summary.json"])
    write_json(out / "summary.json", summary)
    return summary


def format_summary(summary: dict, out: Path) -> str:
    """The human summary ``servo hysteresis`` prints."""
    d = summary["dahl"]
    p, s = d["params"], d["std"]
    ref = summary.get("drive")
    err = summary.get("error_pct", {})
    lines = [f"servo hysteresis: {summary['recording']}"]
    if "small_loop" in summary:
        sl = summary["small_loop"]
        lines.append(f"  small loop: position range {sl['x_range_m'] * 1e6:.2f} um, current range {sl['u_range_A'] * 1e3:.3g} mA")
    lines.append(f"  Dahl fit (scipy least_squares, {d['nfev']} evaluations): residual {d['rel_error_pct']:.3g} % of the loop, "
                 f"saturation {d['saturation']:.2f}, Dahl length Ha/sigma {d['dahl_length_m'] * 1e6:.3g} um")  # fmt: skip
    for k in ("sigma", "Ha", "alpha", "c"):
        line = f"    {k:<6} {p[k]:>12.6g} {d['units'][k]:<4}"
        line += f" +- {s[k]:.2g}" if k in s else " (fixed)"
        if ref:
            line += f"   drive {ref[k]:.6g} ({err[k]:+.2f} %)"
        lines.append(line)
    if "average_slope" in summary:
        a = summary["average_slope"]["params"]
        line = f"  large loop average slope (eq. 11): K = {a['K']:.5g} A/m, Fc = {a['Fc'] * 1e3:.4g} mA, h0 = {a['h0'] * 1e3:.4g} mA"
        if ref:
            line += f"   (drive K {ref['K']:.4g} A/m: {err['K']:+.2f} %)"
        lines.append(line)
    lines.append(f"  wrote {out}/: " + ", ".join(summary["files"]))
    return "\n".join(lines)


__all__ = ["format_summary", "run_hysteresis_recording", "run_hysteresis_simulated"]

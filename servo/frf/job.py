"""The ``servo frf`` job: a recording in, its frequency response from ``u`` to ``x`` out.

Files written into one folder (all computed before the first is written):

* ``frf.npz`` -- the response in the format of :mod:`servo.io.frequency_response`
  (``load_frequency_responses(path)`` -> ``{label: FrequencyResponse}``, and
  ``.to_control()`` for python-control);
* ``frf.csv`` -- the same as a table (f_hz, re, im, mag_db, phase_deg, coherence, rel_std);
* ``frf.mat``, ``frf.h5`` -- the same for MATLAB (scipy.io) and HDF5 (h5py);
* ``frf.png`` -- magnitude with its +-2 std band, phase, coherence;
* ``summary.json`` -- settings, segments, the coherent band, provenance;
* ``report.html`` -- all of it on one self-contained page (:mod:`servo.frf.page`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from servo.errors import RecordingError
from servo.frf.estimate import WelchSettings, h1, instrumental
from servo.io.atomic import write_json
from servo.io.frequency_response import FrequencyResponse, save_csv, save_h5, save_mat, save_npz
from servo.io.plotting import save_figure
from servo.io.provenance import or_default
from servo.io.recording import Recording

#: coherence from which a point counts as measured (the summary's band, the plot's faint points)
COHERENCE_MIN = 0.9


def estimate_frf(rec: Recording, closed_loop: bool = False, settings: WelchSettings | None = None,
                 force_unit: str = "A", f_min: float = 0.0, f_max: float = np.inf,
                 position_unit: str = "m") -> FrequencyResponse:  # fmt: skip
    """The response from ``rec.u`` to ``rec.x`` (``position_unit`` per ``force_unit``:
    m/A, m/N, rad/(N*m) for a rotary axis) between ``f_min`` and ``f_max`` Hz: H1 (open
    loop) or, with ``closed_loop``, ``P_ry/P_ru`` with the recording's reference
    ``rec.r`` as instrument (:mod:`servo.frf.estimate`)."""
    unit = f"{position_unit}/({force_unit})" if "*" in force_unit or "/" in force_unit else f"{position_unit}/{force_unit}"
    if closed_loop:
        if rec.r is None:
            raise RecordingError("frf --closed-loop needs the reference (or the injected excitation) as column r; "
                                 "map one with --columns r=NAME")  # fmt: skip
        resp = instrumental(rec.r, rec.u, rec.x, rec.dt, settings, unit)
    else:
        resp = h1(rec.u, rec.x, rec.dt, settings, unit)
    resp = resp.band(f_min, f_max)
    if resp.f_hz.size == 0:
        raise RecordingError(f"frf: no frequency of the estimate lies in [{f_min:g}, {f_max:g}] Hz")
    resp.meta.update(label="u -> x" + (" (instrument r)" if closed_loop else ""), source=rec.source,
                     columns=rec.meta.get("columns", {}), scale=rec.meta.get("scale", {}))  # fmt: skip
    return resp


def coherent_band(resp: FrequencyResponse, coherence_min: float = COHERENCE_MIN) -> dict:
    """Where the estimate is measured: the points with coherence >= ``coherence_min``,
    their span (Hz) and the median of their relative random error."""
    good = resp.coherence >= coherence_min
    if not good.any():
        return {"coherence_min": coherence_min, "points": 0, "of": int(resp.f_hz.size), "f_lo_hz": None,
                "f_hi_hz": None, "median_rel_std": None}  # fmt: skip
    return {"coherence_min": coherence_min, "points": int(good.sum()), "of": int(resp.f_hz.size),
            "f_lo_hz": float(resp.f_hz[good][0]), "f_hi_hz": float(resp.f_hz[good][-1]),
            "median_rel_std": float(np.median(resp.rel_std[good]))}  # fmt: skip


def summarize(resp: FrequencyResponse, rec: Recording) -> dict:
    m = resp.meta
    return {
        "source": rec.source,
        "samples": rec.n,
        "sample_rate_hz": rec.sample_rate_hz,
        "method": m["method"],
        "unit": resp.unit,
        "welch": {k: m[k] for k in ("nperseg", "overlap", "window", "detrend", "segments", "equivalent_averages",
                                    "resolution_hz")},  # fmt: skip
        "f_hz": [float(resp.f_hz[0]), float(resp.f_hz[-1])],
        "points": int(resp.f_hz.size),
        "coherent": coherent_band(resp),
    }


def write_frf(resp: FrequencyResponse, rec: Recording, out: Path, extra: dict | None = None) -> dict:
    """Write the files of the module docstring into ``out``; returns the summary
    (``extra`` merged in, e.g. the provenance)."""
    from servo.frf.page import page
    from servo.frf.plots import plot_frf

    out = Path(out)
    summary = {**summarize(resp, rec), **(extra or {})}
    summary["provenance"] = or_default(summary.get("provenance"))
    fig = plot_frf(resp, coherence_min=COHERENCE_MIN)
    out.mkdir(parents=True, exist_ok=True)
    label = resp.meta["label"]
    save_npz(out / "frf.npz", {label: resp})
    save_csv(out / "frf.csv", {label: resp})
    save_mat(out / "frf.mat", {label: resp})
    save_h5(out / "frf.h5", {label: resp})
    save_figure(fig, out / "frf.png")
    summary["files"] = ["frf.csv", "frf.h5", "frf.mat", "frf.npz", "frf.png", "report.html", "summary.json"]
    write_json(out / "summary.json", summary)
    page(summary, out).write(out)
    return summary


def format_summary(summary: dict, out: Path) -> str:
    """The lines ``servo frf`` prints."""
    w, c = summary["welch"], summary["coherent"]
    lines = [f"servo frf: {summary['source']}: {summary['samples']} samples at {summary['sample_rate_hz']:g} Hz, "
             f"{summary['method']}",
             f"  Welch: {w['segments']} segments of {w['nperseg']} samples ({w['overlap'] * 100:g} % overlap, "
             f"{w['window']}; {w['equivalent_averages']:.1f} independent averages), {w['resolution_hz']:.4g} Hz apart, "
             f"{summary['f_hz'][0]:.4g}-{summary['f_hz'][1]:.4g} Hz ({summary['points']} points)"]  # fmt: skip
    if c["points"]:
        lines.append(f"  coherence >= {c['coherence_min']:g}: {c['points']} of {c['of']} points, {c['f_lo_hz']:.4g}-"
                     f"{c['f_hi_hz']:.4g} Hz; median random error {100 * c['median_rel_std']:.2g} % of |H|")  # fmt: skip
    else:
        lines.append(f"  no point reaches coherence {c['coherence_min']:g}: the input does not explain the output "
                     "(too little excitation, noise, or a closed loop: try --closed-loop)")  # fmt: skip
    lines.append(f"  wrote {out}/: " + ", ".join(summary["files"]))
    return "\n".join(lines)


__all__ = ["COHERENCE_MIN", "coherent_band", "estimate_frf", "format_summary", "summarize", "write_frf"]

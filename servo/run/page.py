"""``servo run``'s report page (:mod:`servo.io.page`): the tracking figures per run first,
then the segments, the steps, the compute time, the plots and the provenance, from the
run's ``summary.json`` and the PNGs beside it."""
from __future__ import annotations

from pathlib import Path

from servo.io.page import Page, Section, Table, Text, images

#: the run's plots, in the order the page shows them (those a run wrote)
PLOTS = ("tracking.png", "steps.png", "current.png", "pes_compensated.png", "pes_uncompensated.png", "timing.png",
         "lateness.png")


def nm(v) -> float | None:
    return None if v is None else v * 1e9


def _settling(step: dict):
    return "never" if step["settling_ms"] is None else step["settling_ms"]


def page(summary: dict, folder: str | Path | None = None) -> Page:
    """The page of a run's ``summary`` (:func:`servo.run.job.run_job`); the plots are read
    from ``folder`` when given."""
    runs, labels = summary["runs"], list(summary["runs"])
    first = runs[labels[0]]
    head = "; ".join(f"{lab}: tracking error RMS {nm(runs[lab]['error_rms_m']):.1f} nm" for lab in labels)
    lines = [head, f"{summary['ticks']} ticks at {summary['sample_rate_hz'] / 1e3:g} kHz ({summary['duration_s']:g} s "
                   f"simulated), {summary['path']}"]  # fmt: skip
    if summary.get("startup_s") is not None:
        lines.append(f"startup: {summary['startup_s']:.2f} s from process start to the first tick")
    segs = [[seg] + [nm(runs[lab]["error_rms_by_segment_m"][seg]) for lab in labels]
            for seg in first["error_rms_by_segment_m"]]  # fmt: skip
    segs.append(["whole run"] + [nm(runs[lab]["error_rms_m"]) for lab in labels])
    tracking = [Table(segs, ["tracking error RMS (nm)"] + labels, digits=5)]
    if first.get("steps"):
        rows = [[f"{st['size_m'] * 1e6:+.3g} um at {st['t_s']:g} s"]
                + [x for lab in labels for x in (runs[lab]["steps"][i]["overshoot_pct"], _settling(runs[lab]["steps"][i]))]
                for i, st in enumerate(first["steps"])]  # fmt: skip
        tracking.append(Table(rows, ["step"] + [f"{lab} {q}" for lab in labels for q in ("overshoot (%)", "settling (ms)")],
                              "Steps (settling: within the band from then on; never: not by the run's end)"))  # fmt: skip
    if "pes_tracks" in first:
        keys = (("sigma3", "PES 3 sigma"), ("rro_pp", "RRO peak-to-peak"), ("nrro_3sigma", "NRRO 3 sigma"))
        tracking.append(Table([[name] + [runs[lab]["pes_tracks"][k] * 100 for lab in labels] for k, name in keys],
                              ["% of a track"] + labels, "The HDD benchmark's PES"))  # fmt: skip
    keys = ("per_sample_us", "tick_us_median", "tick_us_p99", "tick_us_max", "overruns", "wall_s")
    compute = Table([[k] + [runs[lab].get(k) for lab in labels] for k in keys if k in first], ["compute"] + labels)
    sections = [Section("Tracking", tracking), Section("Compute time", [compute])]
    if folder is not None:
        figs = images(folder, PLOTS)
        if figs:
            sections.append(Section("Figures", figs))
    files = summary.get("files")
    if files:
        sections.append(Section("Files", [Text(", ".join(files))]))
    return Page("servo run", lines, "info", sections, summary.get("provenance"))


__all__ = ["PLOTS", "page"]

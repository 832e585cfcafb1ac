"""``servo frf``'s report page (:mod:`servo.io.page`): where the estimate is measured
first, then the Bode plot, the Welch settings and the provenance, from ``summary.json``."""
from __future__ import annotations

from pathlib import Path

from servo.io.page import Page, Section, Table, Text, images


def page(summary: dict, folder: str | Path | None = None) -> Page:
    """The page of ``servo frf``'s ``summary`` (:func:`servo.frf.job.write_frf`); the
    plot is read from ``folder`` when given."""
    c, w = summary["coherent"], summary["welch"]
    if c["points"]:
        head = (f"coherence >= {c['coherence_min']:g} at {c['points']} of {c['of']} points, {c['f_lo_hz']:.4g}-"
                f"{c['f_hi_hz']:.4g} Hz; median random error {100 * c['median_rel_std']:.2g} % of |H|")  # fmt: skip
    else:
        head = (f"no point reaches coherence {c['coherence_min']:g}: the input does not explain the output (too little "
                "excitation, noise, or a closed loop: try --closed-loop)")  # fmt: skip
    lines = [head, f"{summary['source']}: {summary['samples']} samples at {summary['sample_rate_hz']:g} Hz, "
                   f"{summary['method']}, H in {summary['unit']}"]  # fmt: skip
    settings = Table([["source", summary["source"]], ["samples", summary["samples"]],
                      ["sample rate (Hz)", summary["sample_rate_hz"]], ["method", summary["method"]],
                      ["unit of H", summary["unit"]], ["band (Hz)", f"{summary['f_hz'][0]:.4g}-{summary['f_hz'][1]:.4g}"],
                      ["points", summary["points"]]] + [[f"Welch {k}", v] for k, v in w.items()])  # fmt: skip
    sections = []
    if folder is not None:
        sections.append(Section("Frequency response", images(folder, ["frf.png"])))
    sections.append(Section("Estimate", [settings]))
    if summary.get("files"):
        sections.append(Section("Files", [Text(", ".join(summary["files"]))]))
    return Page("servo frf", lines, "ok" if c["points"] else "warn", sections, summary.get("provenance"))


__all__ = ["page"]

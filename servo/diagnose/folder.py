"""A diagnosis's output folder: ``report.json``, ``final_model.toml``, the plots and the
report page, written from one :class:`~servo.diagnose.job.Diagnosis`."""
from __future__ import annotations

from pathlib import Path

from servo.diagnose.job import Diagnosis
from servo.diagnose.page import page
from servo.diagnose.scope import Unscoped
from servo.diagnose.report import build_report, write_drive_toml, write_report


def write_outputs(D: Diagnosis | Unscoped, out: Path, provenance: dict | None = None, plots: bool = True) -> dict:
    """A diagnosis's folder: ``report.json``, ``final_model.toml`` (when the final model
    is a drive), the plots (``plots``: drawn while the report is written,
    :class:`~servo.diagnose.plots.PlotWriter`) and the page ``report.html``
    (:mod:`servo.diagnose.page`) into ``out`` (a staging folder,
    :func:`servo.io.outdir.staged`); returns the report."""
    files, figures = ["report.json", "report.html"], None
    if isinstance(D, Unscoped):  # out of scope: no rows to plot, no model to write
        report = build_report(D, files)
        report["provenance"] = provenance
        write_report(report, out)
        page(report, out).write(out)
        return report
    if plots:  # drawn beside the report (by a second process), all written before the page that shows them
        from servo.diagnose.plots import PlotWriter

        figures = PlotWriter(D, out)
        files += figures.names
    try:
        report = build_report(D, files + ["final_model.toml"])
        report["provenance"] = provenance
        if not write_drive_toml(report, out):
            report["files"].remove("final_model.toml")
        write_report(report, out)
        if figures is not None:
            figures.finish()
    except BaseException:
        if figures is not None:
            figures.abandon()
        raise
    page(report, out).write(out)
    return report


__all__ = ["write_outputs"]

"""A fleet run's report page (:mod:`servo.io.page`): the counts, the flagged drives and
the outliers first, then the plots, the population of each scored column, the failed
drives, the settings and the provenance, from ``fleet.json`` and the finished rows (the
same content as ``fleet_report.md``, :mod:`servo.fleet.report`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from servo.fleet.report import MAX_LISTED
from servo.io.page import Page, Section, Table, Text, images

#: the fleet's plots (:mod:`servo.fleet.plots`), in the order the page shows them
PLOTS = ("histograms.png", "scatter.png", "findings.png")


def _population(rows: list[dict], columns: list[str]) -> list[list]:
    out = []
    for c in columns:
        x = np.array([float(r[c]) for r in rows if r.get("status") == "ok" and isinstance(r.get(c), (int, float))
                      and not isinstance(r.get(c), bool)])  # fmt: skip
        x = x[np.isfinite(x)]
        if not x.size:
            out.append([c, 0, None, None, None, None])
            continue
        med = float(np.median(x))
        out.append([c, int(x.size), med, float(np.median(np.abs(x - med))), float(x.min()), float(x.max())])
    return out


def page(summary: dict, rows: list[dict], scored: list[str], folder: str | Path | None = None) -> Page:
    """The page of a fleet run's ``summary`` (``fleet.json``), its ``rows`` and the
    ``scored`` columns; the plots are read from ``folder`` when given."""
    s = summary
    lines = [f"servo fleet {s['command']}: {s['drives']} drives, {s['ok']} ok, {s['failed']} failed"
             + (f", {s['resumed']} resumed" if s["resumed"] else "")]  # fmt: skip
    if "flagged" in s:
        lines.append(f"flagged drives (findings, or verdict unexplained/out_of_scope): {len(s['flagged'])}")
    lines.append(f"robust outliers (|z| > {s['outlier_threshold']:g}): {len(s['outliers'])}")
    lines.append(f"ran on {s['ran_on']} in {s['wall_s']:.1f} s")
    status = "bad" if s["failed"] else ("warn" if s["outliers"] or s.get("flagged") else "ok")
    sections = []
    if "flagged" in s:
        flagged = [r for r in rows if r.get("status") == "ok" and r.get("flagged")][:MAX_LISTED]
        sections.append(Section(f"Flagged drives ({len(s['flagged'])})", [
            Table([[r["drive"], r.get("findings") or None, r.get("verdict"), r.get("flag_reason")] for r in flagged],
                  ["drive", "findings", "verdict", "reason"]) if flagged else Text("None.")]))  # fmt: skip
    out = s["outliers"][:MAX_LISTED]
    sections.append(Section(f"Robust outliers ({len(s['outliers'])})", [
        Table([[o["drive"], o["column"], o["value"], o["median"], o["z"]] for o in out],
              ["drive", "column", "value", "median", "z"], digits=4) if out else Text("None."),
        Text(f"Not scored: {', '.join(s['not_scored'])}" if s.get("not_scored") else "")]))  # fmt: skip
    if folder is not None:
        figs = images(folder, PLOTS)
        if figs:
            sections.append(Section("Figures", figs))
    sections.append(Section("Population", [Table(_population(rows, scored), ["column", "drives", "median", "MAD", "min",
                                                                             "max"])]))  # fmt: skip
    failed = [r for r in rows if r.get("status") != "ok"][:MAX_LISTED]
    if failed:
        sections.append(Section(f"Failed drives ({s['failed']})", [Table([[r["drive"], r.get("error")] for r in failed],
                                                                          ["drive", "error"])]))  # fmt: skip
    sections.append(Section("Run", [Table([["table", s["table"]], ["settings", s["settings"]]]),
                                   Text(", ".join(s.get("files", [])))]))  # fmt: skip
    prov = s.get("provenance") or {"versions": s.get("versions")}
    return Page(f"servo fleet {s['command']}", lines, status, sections, prov)


__all__ = ["PLOTS", "page"]

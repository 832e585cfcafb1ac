"""A fleet run: tasks -> rows on Dask -> table, outliers, report and plots in one folder.

Writes into ``out``:

* ``fleet.parquet``: one row per drive (:mod:`servo.fleet.table`).  While the fleet
  runs it holds the drives done so far, rewritten atomically every
  :data:`CHECKPOINT_S` seconds, so that a run stopped half-way (a Ctrl-C, a lost client)
  continues with ``--resume``; at the end, every drive in the order given;
* ``fleet_report.md`` (:mod:`servo.fleet.report`), ``fleet.json`` (the summary, strict
  JSON);
* ``histograms.png``, ``scatter.png`` and, for a diagnosis, ``findings.png``
  (:mod:`servo.fleet.plots`), unless ``plots`` is off.

``resume``: the drives of an earlier ``fleet.parquet`` in ``out`` whose key (content
hash and settings, :func:`servo.fleet.task.task_key`) matches and that succeeded are
taken as they are; only the others run.
"""
from __future__ import annotations

import importlib
import time
from pathlib import Path

from servo.fleet import plots as fleet_plots
from servo.fleet import runner, table
from servo.fleet.outliers import outliers
from servo.fleet.report import format_report
from servo.fleet.task import ADAPTERS, Task, canonical
from servo.io.atomic import atomic_write, write_json
from servo.io.progress import stage

CHECKPOINT_S = 5.0


class _Checkpoint:
    """Rows as they complete; the table of those so far, at most every ``every_s``."""

    def __init__(self, path: Path, kept: list[dict], every_s: float, then=None):
        self.path, self.rows, self.every_s, self.then = path, list(kept), every_s, then
        self.last = time.perf_counter()

    def __call__(self, rows: list[dict]) -> None:
        self.rows += rows
        if time.perf_counter() - self.last >= self.every_s:
            table.write(self.path, self.rows)
            self.last = time.perf_counter()
        if self.then is not None:
            self.then(rows)


def run_fleet(command: str, tasks: list[Task], settings: dict, out: str | Path, where: runner.Where = runner.Where(),
              resume: bool = False, plots: bool = True, progress=None) -> dict:  # fmt: skip
    """Run ``tasks`` of ``command`` and write the outputs into ``out`` (see module doc).
    ``progress``: called with each batch's rows (e.g. :class:`servo.fleet.runner.Progress`).
    Returns the summary (``fleet.json``)."""
    where.check()
    adapter = importlib.import_module(ADAPTERS[command])
    out = Path(out)
    path = out / table.NAME
    done = table.done_rows(path) if resume else {}
    kept = {t.key: {**done[t.key], "drive": t.drive, "source": t.source} for t in tasks if t.key in done}
    todo = [t for t in tasks if t.key not in kept]
    if kept and hasattr(progress, "start"):
        progress.start(len(todo))
    t0 = time.perf_counter()
    check = _Checkpoint(path, list(kept.values()), CHECKPOINT_S, progress)
    new = runner.run(command, todo, settings, where, getattr(adapter, "BATCH", 1), check)
    wall = time.perf_counter() - t0
    stage("the table, report and plots")
    by_key = {**kept, **{r["key"]: r for r in new}}
    rows = [by_key[t.key] for t in tasks]
    out.mkdir(parents=True, exist_ok=True)
    table.write(path, rows)

    cols = table.columns_of(rows)
    scored, pairs = adapter.scored(cols), adapter.pairs(cols)
    found = outliers(rows, scored)
    files = [table.NAME, "fleet.json", "fleet_report.md"]
    if plots:
        fleet_plots.save(fleet_plots.histograms(rows, scored), out / "histograms.png")
        fleet_plots.save(fleet_plots.scatters(rows, pairs), out / "scatter.png")
        files += ["histograms.png", "scatter.png"]
        if command == "diagnose":
            fleet_plots.save(fleet_plots.findings(rows), out / "findings.png")
            files.append("findings.png")
    ok = [r for r in rows if r["status"] == "ok"]
    summary = {
        "command": command,
        "drives": len(rows),
        "ok": len(ok),
        "failed": len(rows) - len(ok),
        "resumed": len(kept),
        "ran_on": runner.describe(where, len(todo)),
        "wall_s": wall,
        "settings": canonical(settings),
        "table": str(path),
        "outliers": [o.__dict__ for o in found],
        "files": sorted(files),
    }
    if command == "diagnose":
        summary["flagged"] = [r["drive"] for r in ok if r.get("flagged")]
    atomic_write(out / "fleet_report.md", lambda tmp: Path(tmp).write_text(format_report(summary, rows, scored, found)))
    write_json(out / "fleet.json", summary)
    return summary


def format_summary(summary: dict, out: str | Path) -> str:
    """The lines the command prints."""
    s = summary
    lines = [f"servo fleet {s['command']}: {s['drives']} drives, {s['ok']} ok, {s['failed']} failed"
             + (f", {s['resumed']} resumed" if s["resumed"] else "") + f"; ran on {s['ran_on']} in {s['wall_s']:.1f} s"]  # fmt: skip
    if "flagged" in s:
        names = ", ".join(s["flagged"][:20]) + (" ..." if len(s["flagged"]) > 20 else "")
        lines.append(f"  flagged drives (findings, or verdict unexplained/out_of_scope): {len(s['flagged'])}"
                     + (f" ({names})" if names else ""))  # fmt: skip
    lines.append(f"  robust outliers (|z| > 3.5): {len(s['outliers'])} (listed in fleet_report.md)")
    lines.append(f"  wrote {out}/: " + ", ".join(s["files"]))
    return "\n".join(lines)


__all__ = ["CHECKPOINT_S", "format_summary", "run_fleet"]

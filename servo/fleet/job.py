"""A fleet run: tasks -> rows on Dask -> table, outliers, report and plots in one folder.

Writes into ``out`` (a new or empty folder), staged like every command's outputs
(:func:`servo.io.outdir.staged`): everything is written into ``OUT.incomplete/``, which
is renamed to ``OUT`` when the last file is written, so ``OUT`` is complete or absent;
one writer per output (a second fleet given the same ``OUT`` is refused):

* ``fleet.parquet``: one row per drive (:mod:`servo.fleet.table`), every drive in the
  order given.  While the fleet runs, ``OUT.incomplete/fleet.parquet`` holds the drives
  done so far, rewritten atomically every :data:`CHECKPOINT_S` seconds; a run stopped
  half-way (Ctrl-C, a fault, a full disk) leaves that folder, and the error line says
  how to continue it (``resume``);
* ``fleet_report.md`` (:mod:`servo.fleet.report`), ``fleet.json`` (the summary, strict
  JSON, with the provenance: :func:`servo.io.provenance.provenance`, which the table's
  schema metadata holds too, with each column's unit);
* ``dask.log``: the records and warnings of Dask itself, when there are some (they
  stay off stderr);
* ``histograms.png``, ``scatter.png`` and, for a diagnosis, ``findings.png``
  (:mod:`servo.fleet.plots`), unless ``plots`` is off;
* ``report.html``: all of it on one self-contained page (:mod:`servo.fleet.page`).

``resume``: an earlier fleet (its folder, its ``fleet.parquet``, or the folder of an
interrupted one, whose staging folder is then continued when it is ``out``'s own).  A
drive of it is taken as it is when it succeeded and its row was made from the same
recording path (or simulated drive) under the same key
(:func:`servo.fleet.task.task_key`: content hash, settings, column mapping, scales,
code versions); only the others run.
"""
from __future__ import annotations

import importlib
import os
import time
from pathlib import Path

from servo.errors import ConfigError
from servo.fleet import runner, table
from servo.fleet.outliers import THRESHOLD, outliers, unscored
from servo.fleet.report import format_report
from servo.fleet.page import page
from servo.fleet.task import ADAPTERS, Task, canonical, code_versions
from servo.io.atomic import atomic_write, write_json
from servo.io.outdir import staged, staging_dir
from servo.io.page import NAME as PAGE
from servo.io.provenance import provenance
from servo.io.progress import stage

CHECKPOINT_S = 5.0
#: where Dask's own log records and warnings go (only when there are some)
DASK_LOG = "dask.log"


class _Checkpoint:
    """Rows as they complete; the table of those so far, at most every ``every_s``."""

    def __init__(self, path: Path, kept: list[dict], every_s: float, then=None, meta: dict | None = None):
        self.path, self.rows, self.every_s, self.then = path, list(kept), every_s, then
        self.meta = meta or {}  # table.write's provenance and force unit
        self.last = time.perf_counter()

    def __call__(self, rows: list[dict]) -> None:
        self.rows += rows
        if time.perf_counter() - self.last >= self.every_s:
            table.write(self.path, self.rows, **self.meta)
            self.last = time.perf_counter()
        if self.then is not None:
            self.then(rows)


def earlier_table(resume: str | Path, out: str | Path) -> Path | None:
    """The table of the earlier fleet ``resume`` names: a ``fleet.parquet``, a fleet's
    folder, or a folder whose command was interrupted (its ``.incomplete`` staging
    folder).  None when ``resume`` is ``out`` and nothing of it exists yet (a first run
    of a script that always resumes); otherwise one line if there is no table."""
    r = Path(os.path.abspath(resume))
    for cand in (r, r / table.NAME, staging_dir(r) / table.NAME):
        if cand.is_file():
            return cand
    if r in (Path(os.path.abspath(out)), staging_dir(out)):
        return None
    raise ConfigError(f"fleet: --resume {resume}: no fleet table there ({table.NAME}, or that of an interrupted run in "
                      f"{staging_dir(r)}/)")  # fmt: skip


def _merge(tasks: list[Task], kept: dict[int, dict], new: list[dict]) -> list[dict]:
    """Every task's row in the tasks' order: the kept rows at their positions, the new
    ones (in the order of the tasks run) in the others."""
    it = iter(new)
    return [kept[i] if i in kept else next(it) for i in range(len(tasks))]


def run_fleet(command: str, tasks: list[Task], settings: dict, out: str | Path, where: runner.Where = runner.Where(),
              resume: str | Path | None = None, plots: bool = True, progress=None) -> dict:  # fmt: skip
    """Run ``tasks`` of ``command`` and write the outputs into the new folder ``out``
    (see module doc), reusing the matching rows of the earlier fleet ``resume``.
    ``progress``: called with each batch's rows (e.g. :class:`servo.fleet.runner.Progress`).
    Returns the summary (``fleet.json``)."""
    where.check()
    adapter = importlib.import_module(ADAPTERS[command])
    out = Path(out)
    earlier = earlier_table(resume, out) if resume is not None else None
    done = table.done_rows(earlier) if earlier is not None else {}
    kept = {i: {**done[(t.source, t.key)], "drive": t.drive} for i, t in enumerate(tasks) if (t.source, t.key) in done}
    todo = [t for i, t in enumerate(tasks) if i not in kept]
    where = runner.placed(where, len(todo), getattr(adapter, "CLUSTER_MIN", runner.IN_PROCESS_MAX + 1))
    adopt = earlier is not None and earlier.parent == staging_dir(out)
    hint = f"continue with --resume {out} --out {out}"
    meta = {"provenance": provenance(), "force_unit": settings.get("force_unit", "A")}  # the table's schema metadata
    with staged(out, keep_partial=True, resume=adopt, kept="the drives done so far", hint=hint) as tmp:
        for f in tmp.iterdir():  # an interrupted run's other files: rewritten below, or not at all
            if f.is_file() and f.name not in (table.NAME, DASK_LOG):
                f.unlink()
        if kept and hasattr(progress, "start"):
            progress.start(len(todo))
        t0 = time.perf_counter()
        check = _Checkpoint(tmp / table.NAME, list(kept.values()), CHECKPOINT_S, progress, meta)
        with runner.dask_logs(tmp / DASK_LOG):  # Dask's records and warnings, not on stderr
            new = runner.run(command, todo, settings, where, getattr(adapter, "BATCH", 1), check,
                             on_client=getattr(progress, "connected", None))  # fmt: skip
        wall = time.perf_counter() - t0
        stage("the table, report and plots")
        rows = _merge(tasks, kept, new)
        table.write(tmp / table.NAME, rows, **meta)
        summary = _outputs(command, adapter, rows, settings, tmp, out, plots, where, len(kept), len(todo), wall,
                           meta["provenance"])  # fmt: skip
    return summary


def _outputs(command, adapter, rows, settings, tmp: Path, out: Path, plots: bool, where, n_kept: int, n_todo: int,
             wall: float, prov: dict | None = None) -> dict:  # fmt: skip
    """Outliers, report, plots and ``fleet.json`` of the finished ``rows``, written into ``tmp``."""
    cols = table.columns_of(rows)
    scored, pairs = adapter.scored(cols), adapter.pairs(cols)
    shown = adapter.figures(cols) if hasattr(adapter, "figures") else scored
    found = outliers(rows, scored)
    files = [table.NAME, "fleet.json", "fleet_report.md", PAGE] + [DASK_LOG] * (tmp / DASK_LOG).exists()
    if plots:
        from servo.fleet import plots as fleet_plots  # matplotlib: only when plots are asked for

        fleet_plots.save(fleet_plots.histograms(rows, shown), tmp / "histograms.png")
        fleet_plots.save(fleet_plots.scatters(rows, pairs), tmp / "scatter.png")
        files += ["histograms.png", "scatter.png"]
        if command == "diagnose":
            fleet_plots.save(fleet_plots.findings(rows), tmp / "findings.png")
            files.append("findings.png")
    ok = [r for r in rows if r["status"] == "ok"]
    summary = {
        "command": command,
        "drives": len(rows),
        "ok": len(ok),
        "failed": len(rows) - len(ok),
        "resumed": n_kept,
        "ran_on": runner.describe(where, n_todo),
        "wall_s": wall,
        "settings": canonical(settings),
        "versions": code_versions(),
        "table": str(out / table.NAME),
        "outliers": [o.__dict__ for o in found],
        "outlier_threshold": THRESHOLD,
        "not_scored": unscored(rows, scored),
        "files": sorted(files),
        "provenance": prov,
    }
    if command == "diagnose":
        summary["flagged"] = [r["drive"] for r in ok if r.get("flagged")]
    atomic_write(tmp / "fleet_report.md", lambda p: Path(p).write_text(format_report(summary, rows, shown, found)))
    write_json(tmp / "fleet.json", summary)
    page(summary, rows, shown, tmp).write(tmp)
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
    lines.append(f"  robust outliers (|z| > {s['outlier_threshold']:g}): {len(s['outliers'])} (listed in fleet_report.md)")
    lines.append(f"  wrote {out}/: " + ", ".join(s["files"]))
    return "\n".join(lines)


__all__ = ["CHECKPOINT_S", "DASK_LOG", "earlier_table", "format_summary", "run_fleet"]

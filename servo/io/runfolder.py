"""A ``servo run`` output folder loaded back: its logs with named columns and units, its
config and its summary.

``load_run(path)`` reads ``log_<label>.npz`` (or ``log_<label>.csv`` when a run wrote
only CSV) for each run in the folder, ``config.toml`` and ``summary.json``.  A folder an
interrupted run left (``OUT.incomplete/``) loads too: its summary is None.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kernels.compose import LOG_COLUMNS, LOG_UNITS
from servo.config import Config, load_config
from servo.errors import RecordingError
from servo.io.tables import read_table


@dataclass
class RunFolder:
    """The contents of a ``servo run`` output folder.

    ``logs``: label (``compensated``, ``uncompensated``) -> column name -> array
    (rows,); ``units``: column -> unit; ``meta``: label -> the log's meta (rows, seed,
    path...); ``config``: the run's effective :class:`~servo.config.Config` (rerun it for
    the same bits); ``summary``: ``summary.json`` as a dict, None for an interrupted run.
    """

    path: Path | None
    logs: dict[str, dict[str, np.ndarray]]
    config: Config | None
    summary: dict | None
    meta: dict[str, dict] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=lambda: dict(LOG_UNITS))

    @property
    def labels(self) -> list[str]:
        return list(self.logs)

    def _figures(self) -> list[tuple[str, str]]:
        """(label, one line of its figures) per run."""
        out = []
        for label, log in self.logs.items():
            n = len(next(iter(log.values()))) if log else 0
            runs = (self.summary or {}).get("runs") or {}
            rms = runs.get(label, {}).get("error_rms_m")
            out.append((label, f"{n} rows" + (f", tracking error RMS {rms * 1e9:.1f} nm" if rms is not None else "")))
        return out

    def __repr__(self) -> str:
        where = "in memory" if self.path is None else str(self.path)
        kind = self.config.controller.kind if self.config is not None else "?"
        runs = "; ".join(f"{label}: {text}" for label, text in self._figures())
        return f"<servo run ({where}), controller {kind}: {runs}>"

    def _repr_html_(self) -> str:
        """The run's summary as a report page's content (:mod:`servo.io.page`)."""
        from servo.io.page import Page, Section, Table

        head = repr(self).split(":")[0].lstrip("<")
        runs = Section("Runs", [Table([list(x) for x in self._figures()], ["run", "figures"])])
        return Page(head, [text for _, text in self._figures()], "info", [runs],
                    (self.summary or {}).get("provenance")).fragment()

    def rows(self, label: str) -> np.ndarray:
        """The log of run ``label`` as one array (rows, len(LOG_COLUMNS)), in the column
        order of :data:`kernels.compose.LOG_COLUMNS` (what :func:`servo.run.plots.plot_run`
        takes)."""
        log = self.logs[label]
        return np.column_stack([log[c] for c in LOG_COLUMNS])


def _read_log(npz: Path, csv: Path) -> tuple[dict[str, np.ndarray], dict]:
    """A log's columns and meta, through :func:`~servo.io.tables.read_table` (each column
    within its budget; a CSV header's units, ``t [s]``, split off)."""
    path = npz if npz.exists() else csv
    try:
        table = read_table(path)
        meta = json.loads(str(table.pop("meta"))) if "meta" in table else {}
    except (RecordingError, ValueError) as exc:
        raise RecordingError(f"{path}: not a readable run log ({str(exc).removeprefix('recording: ')})") from None
    return dict(table), meta if isinstance(meta, dict) else {}


def run_plugins(summary: dict | None) -> list[str]:
    """The ``--plugin`` modules of the command that made a run (its provenance)."""
    argv = ((summary or {}).get("provenance") or {}).get("command") or []
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--plugin"] + [
        a.split("=", 1)[1] for a in argv if a.startswith("--plugin=")]


def load_run(path: str | Path, plugins: list[str] | None = None) -> RunFolder:
    """Load the ``servo run`` output folder ``path`` (see :class:`RunFolder`).  A run of
    a plug-in controller kind needs its module to read its config: ``plugins`` (module
    names or ``.py`` paths, as ``--plugin`` takes them), by default the ones the run's
    command line loaded (from the current folder, as it did)."""
    path = Path(path)
    if not path.is_dir():
        raise RecordingError(f"{path}: no such run folder")
    logs, metas = {}, {}
    for label in ("compensated", "uncompensated"):
        npz, csv = path / f"log_{label}.npz", path / f"log_{label}.csv"
        if npz.exists() or csv.exists():
            logs[label], metas[label] = _read_log(npz, csv)
    if not logs:
        journals = sorted(p.name for p in path.glob("*.journal"))
        hint = f" (it has {', '.join(journals)}: `servo recover` them first)" if journals else ""
        raise RecordingError(f"{path}: no run log (log_compensated/log_uncompensated .npz or .csv){hint}")
    missing = [c for log in logs.values() for c in LOG_COLUMNS if c not in log]
    if missing:
        raise RecordingError(f"{path}: a run log lacks the columns {sorted(set(missing))}")
    summary_path = path / "summary.json"
    try:
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else None
    except ValueError as exc:
        raise RecordingError(f"{summary_path}: not JSON ({exc})") from None
    config = None
    if (path / "config.toml").exists():
        from servo.controllers.plugins import load_plugins

        load_plugins(run_plugins(summary) if plugins is None else plugins)
        config = load_config(path / "config.toml")
    return RunFolder(path, logs, config, summary, metas)


__all__ = ["RunFolder", "load_run", "run_plugins"]

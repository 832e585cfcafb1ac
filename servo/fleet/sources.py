"""The recordings of a fleet: paths, globs or a manifest CSV, each with its column
mapping, scales and content hash.

A manifest is a CSV with a header row and a ``path`` column; optional ``drive`` (the
drive's name in the table; default the file's stem), ``columns`` and ``scale`` (the
``--columns``/``--scale`` syntax, e.g. ``u=vir,x=qm``).  Relative paths are relative to
the manifest's folder.  Paths are made absolute, so that workers on other machines of a
shared file system find them: the workers read the recordings, the scheduler never
carries their data.  The content hash (SHA-256 of the file's bytes) is read here, by the
client, to key ``--resume`` with the mapping, the scales and the settings.
"""
from __future__ import annotations

import csv
import glob
import hashlib
import itertools
from dataclasses import dataclass
from pathlib import Path

from servo.errors import ConfigError, RecordingError
from servo.fleet.task import MAX_DRIVES, Task, check_size, code_versions, task_key
from servo.io.recording import parse_mapping

HASH_BLOCK = 1 << 20


@dataclass(frozen=True)
class Source:
    """One recording: ``drive`` name, absolute ``path``, ``columns`` and ``scale``
    mappings (``"u=vir,x=qm"`` text, "" for none) and the file's ``sha256``."""

    drive: str
    path: str
    columns: str = ""
    scale: str = ""
    sha256: str = ""


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes (hex); one line naming the file if it cannot be read."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(HASH_BLOCK), b""):
                h.update(block)
    except OSError as exc:
        raise RecordingError(f"recording: {path}: {exc.strerror or exc}") from None
    return h.hexdigest()


def expand(patterns: list[str]) -> list[Path]:
    """Paths and globs -> existing files, in the order given (a glob's matches sorted);
    a pattern that matches nothing is an error."""
    out = []
    for p in patterns:
        if any(c in p for c in "*?["):
            hits = sorted(Path(x) for x in glob.glob(p, recursive=True) if Path(x).is_file())
            if not hits:
                raise ConfigError(f"fleet: {p}: no file matches")
            out += hits
        else:
            if not Path(p).is_file():
                raise ConfigError(f"fleet: {p}: no such file")
            out.append(Path(p))
    return out


def read_manifest(path: str | Path) -> list[Source]:
    """The sources of a manifest CSV (see module doc), hashes not yet filled."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(itertools.islice(csv.DictReader(f), MAX_DRIVES + 1))  # no more than the budget is read
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ConfigError(f"fleet: manifest {path}: cannot read it: {exc}") from None
    if not rows or "path" not in rows[0]:
        raise ConfigError(f"fleet: manifest {path}: expected a header row with a 'path' column and one row per recording")
    check_size(len(rows), f"manifest {path}", more=True)
    out = []
    for i, row in enumerate(rows, 2):
        p = (row.get("path") or "").strip()
        if not p:
            raise ConfigError(f"fleet: manifest {path}, line {i}: empty path")
        full = Path(p) if Path(p).is_absolute() else path.parent / p
        if not full.is_file():
            raise ConfigError(f"fleet: manifest {path}, line {i}: {p}: no such file")
        cols, scale = (row.get("columns") or "").strip(), (row.get("scale") or "").strip()
        try:
            parse_mapping(cols, "columns")
            parse_mapping(scale, "scale")
        except RecordingError as exc:
            raise ConfigError(f"fleet: manifest {path}, line {i}: {exc}") from None
        out.append(Source((row.get("drive") or "").strip() or full.stem, str(full.resolve()), cols, scale))
    return out


def sources(patterns: list[str], manifest: str | None = None, columns: str | None = None,
            scale: str | None = None) -> list[Source]:  # fmt: skip
    """Every recording of the command line, hashed: the manifest's, then the paths and
    globs (with the common ``columns``/``scale``).  Drive names must be unique."""
    parse_mapping(columns, "--columns")
    parse_mapping(scale, "--scale")
    items = read_manifest(manifest) if manifest else []
    paths = expand(patterns)
    check_size(len(items) + len(paths), "recordings")
    items += [Source(p.stem, str(p.resolve()), columns or "", scale or "") for p in paths]
    if not items:
        raise ConfigError("fleet: no recordings: give paths, globs or --manifest FILE")
    seen: dict[str, str] = {}
    for s in items:
        if s.drive in seen:
            raise ConfigError(f"fleet: two recordings are named {s.drive!r} ({seen[s.drive]} and {s.path}); "
                              "name them in a manifest's drive column")  # fmt: skip
        seen[s.drive] = s.path
    return [Source(s.drive, s.path, s.columns, s.scale, file_sha256(s.path)) for s in items]


def recording_tasks(items: list[Source], settings: dict) -> list[Task]:
    """One task per recording, keyed (:func:`servo.fleet.task.task_key`) by its content
    hash, ``settings``, its column mapping and scales, and the code's versions."""
    versions = code_versions()
    return [Task(s.drive, task_key(s.sha256, settings, {"columns": s.columns, "scale": s.scale}, versions), s.path,
                 s.sha256, s) for s in items]  # fmt: skip


__all__ = ["Source", "recording_tasks", "expand", "file_sha256", "read_manifest", "sources"]

"""The results table: one row per drive, as Parquet (pyarrow).

Columns: :data:`servo.fleet.task.LEADING` (drive, status, error, source, sha256, key),
then the command's columns sorted by name (a drive lacking a column has a null), then
:data:`servo.fleet.task.TRAILING` (settings as canonical JSON, servo version).  The
order of the columns depends only on which columns there are, and the order of the rows
on the order of the inputs, so two runs of the same fleet give equal tables, however
their tasks were scheduled.  Written atomically (a temporary renamed into place): a
reader, and ``--resume``, never see a half-written file.
"""
from __future__ import annotations

import os
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from servo.errors import ConfigError
from servo.fleet.task import LEADING, TRAILING
from servo.io.atomic import atomic_write

NAME = "fleet.parquet"


def columns_of(rows: list[dict]) -> list[str]:
    """The table's column order for ``rows`` (see module doc)."""
    names: set[str] = set()
    for r in rows:
        names.update(r)
    middle = sorted(names - set(LEADING) - set(TRAILING))
    return [c for c in LEADING] + middle + [c for c in TRAILING]


def to_table(rows: list[dict]) -> pa.Table:
    """``rows`` (dicts) as an Arrow table, columns in :func:`columns_of` order."""
    cols = columns_of(rows)
    return pa.table({c: pa.array([r.get(c) for r in rows]) for c in cols})


def write(path: str | Path, rows: list[dict]) -> pa.Table:
    """Write ``rows`` as Parquet at ``path``, atomically; returns the table.  An error
    of the file system (a full disk) names ``path`` (pyarrow's names no file)."""
    table = to_table(rows)
    Path(path).parent.mkdir(parents=True, exist_ok=True)

    def parquet(tmp):
        try:
            pq.write_table(table, tmp)
        except OSError as exc:
            raise OSError(exc.errno, os.strerror(exc.errno) if exc.errno else str(exc), str(path)) from None

    atomic_write(Path(path), parquet)
    return table


def read(path: str | Path) -> pa.Table:
    """A fleet table; one line if it cannot be read."""
    try:
        return pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise ConfigError(f"fleet: {path}: not a readable fleet table ({exc})") from None


def rows_of(table: pa.Table) -> list[dict]:
    """The table's rows as dicts (a null is None)."""
    return table.to_pylist()


def done_rows(path: str | Path) -> dict[tuple[str, str], dict]:
    """For ``--resume``: (source, key) -> row of every drive of an earlier table that
    succeeded (``status`` ok); empty if there is no table yet.  A row belongs to its
    recording's path (or simulated drive) as well as to its key: two recordings with
    the same bytes are two drives."""
    path = Path(path)
    if not path.exists():
        return {}
    table = read(path)
    if not {"key", "status", "source"} <= set(table.column_names):
        raise ConfigError(f"fleet: {path}: not a fleet table (no source, key and status columns)")
    return {(r["source"], r["key"]): r for r in rows_of(table) if r["status"] == "ok"}


__all__ = ["NAME", "columns_of", "done_rows", "read", "rows_of", "to_table", "write"]

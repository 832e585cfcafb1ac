"""The results table: one row per drive, as Parquet (pyarrow).

Columns: :data:`servo.fleet.task.LEADING` (drive, status, error, source, sha256, key),
then the command's columns sorted by name (a drive lacking a column has a null), then
:data:`servo.fleet.task.TRAILING` (settings as canonical JSON, servo version).  The
order of the columns depends only on which columns there are, and the order of the rows
on the order of the inputs, so two runs of the same fleet give equal tables, however
their tasks were scheduled.  Written atomically (a temporary renamed into place): a
reader, and ``--resume``, never see a half-written file.  The schema's metadata holds
the fleet's provenance and each column's unit (:func:`units_of`;
:func:`servo.io.provenance.schema_metadata`): ``pq.read_schema(path).metadata``.
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


#: a column's unit from the end of its name (the first that matches)
SUFFIX_UNITS = (("_pct", "%"), ("_pct_before", "%"), ("_pct_after", "%"), ("_m_s", "m/s"), ("_ms", "ms"),
                ("_us", "us"), ("_hz", "Hz"), ("_m", "m"), ("_s", "s"))  # fmt: skip


def units_of(columns: list[str], force_unit: str = "A") -> dict[str, str]:
    """The unit of each column whose unit is known: a diagnosis's ``physics.param`` (and
    its ``_std``) from the term's template, an identification's ``J``, ``B``, ``Fc``,
    ``K``, ``h0`` (and ``_std``), with forces in ``force_unit``; else from the name's
    end (:data:`SUFFIX_UNITS`: ``error_rms_m`` is in m).  Positions are in m (a fleet's
    recordings are of the linear model)."""
    from servo.diagnose.terms import VOCABULARY
    from servo.identify.regressors import units as eq3_units
    from servo.io.units import substitute

    eq3 = eq3_units(force_unit)
    out = {}
    for c in columns:
        base = c.removesuffix("_std")
        physics, _, param = base.partition(".")
        if param and physics in VOCABULARY:
            out[c] = substitute(VOCABULARY[physics].unit(param, "F"), force_unit, "m", "F")
        elif base in eq3:
            out[c] = eq3[base]
        else:
            unit = next((u for end, u in SUFFIX_UNITS if c.lower().endswith(end)), None)
            if unit is not None:
                out[c] = unit
    return out


def write(path: str | Path, rows: list[dict], provenance: dict | None = None, force_unit: str = "A") -> pa.Table:
    """Write ``rows`` as Parquet at ``path``, atomically; returns the table.  With
    ``provenance``, the schema's metadata holds it and the columns' units
    (:func:`units_of`).  An error of the file system (a full disk) names ``path``
    (pyarrow's names no file)."""
    table = to_table(rows)
    if provenance is not None:
        from servo.io.provenance import schema_metadata

        table = table.replace_schema_metadata(schema_metadata(provenance, units_of(table.column_names, force_unit)))
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

"""Run logs: preallocated rows, streamed to disk in blocks, finalised atomically.

While a run goes, completed blocks of rows are appended to ``<name>.journal`` (one JSON
header line, then raw little-endian float64 rows) and flushed, so a crash, a Ctrl-C or a
kill loses at most the rows of the current block.  :meth:`RunLog.close` (called on every
exit path by the context manager) writes ``<name>.npz`` and ``<name>.csv`` under
temporary names, renames them into place and removes the journal: a reader never sees a
half-written NPZ or CSV.  :func:`read_journal` recovers the rows of a journal a hard kill
left behind.

NPZ: one float64 array per column (``t``, ``x``, ``u``...) plus ``meta`` (a JSON string).
CSV: a header row of column names, then one row per sample, ``%.17g`` (exact round trip).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from servo.io.atomic import atomic_write


def write_npz(path: Path, columns, data: np.ndarray, meta: dict) -> None:
    """Atomically write ``data`` (rows, len(columns)) as one array per column."""
    arrays = {c: np.ascontiguousarray(data[:, i]) for i, c in enumerate(columns)}
    arrays["meta"] = np.array(json.dumps(meta))

    def w(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    atomic_write(path, w)


def write_csv(path: Path, columns, data: np.ndarray) -> None:
    """Atomically write ``data`` as CSV with a header row."""

    def w(tmp):
        with open(tmp, "w", encoding="ascii") as fh:
            fh.write(",".join(columns) + "\n")
            np.savetxt(fh, data, fmt="%.17g", delimiter=",")

    atomic_write(path, w)


class RunLog:
    """A preallocated log of ``n_rows`` rows of ``columns``, journalled in blocks.

    Fill rows in place (``data[rows]``), advance ``rows``, call :meth:`maybe_flush`.
    Use as a context manager; :meth:`close` finalises whatever was recorded.
    """

    def __init__(self, out_dir: str | Path, name: str, columns, n_rows: int, meta: dict | None = None, block_rows: int = 8192):
        self.dir = Path(out_dir)
        self.name = name
        self.columns = tuple(columns)
        self.meta = dict(meta or {})
        self.block_rows = block_rows
        self.data = np.full((n_rows, len(self.columns)), np.nan)
        self.rows = 0
        self.flushed = 0
        self.closed = False
        self.journal_path = self.dir / f"{name}.journal"
        self.dir.mkdir(parents=True, exist_ok=True)
        self._journal = open(self.journal_path, "wb")
        header = {"columns": self.columns, "meta": self.meta}
        self._journal.write((json.dumps(header) + "\n").encode())
        self._journal.flush()

    @property
    def npz_path(self) -> Path:
        return self.dir / f"{self.name}.npz"

    @property
    def csv_path(self) -> Path:
        return self.dir / f"{self.name}.csv"

    def maybe_flush(self) -> None:
        if self.rows - self.flushed >= self.block_rows:
            self.flush()

    def flush(self) -> None:
        """Append the rows recorded since the last flush to the journal."""
        if self.rows > self.flushed:
            self._journal.write(np.ascontiguousarray(self.data[self.flushed : self.rows], dtype="<f8").tobytes())
            self._journal.flush()  # to the OS: survives a crash of this process, costs no fsync in the loop
            self.flushed = self.rows

    def recorded(self) -> np.ndarray:
        """The rows recorded so far (a view)."""
        return self.data[: self.rows]

    def close(self) -> None:
        """Finalise: NPZ and CSV of every recorded row, atomically; remove the journal."""
        if self.closed:
            return
        self.closed = True
        self.flush()
        self._journal.close()
        self.meta["rows"] = self.rows
        write_npz(self.npz_path, self.columns, self.recorded(), self.meta)
        write_csv(self.csv_path, self.columns, self.recorded())
        self.journal_path.unlink()

    def __enter__(self) -> "RunLog":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_journal(path: str | Path) -> tuple[tuple[str, ...], np.ndarray, dict]:
    """Columns, complete rows and meta of a journal left by an interrupted run."""
    raw = Path(path).read_bytes()
    head, _, body = raw.partition(b"\n")
    header = json.loads(head)
    cols = tuple(header["columns"])
    width = 8 * len(cols)
    body = body[: len(body) - len(body) % width]
    data = np.frombuffer(body, dtype="<f8").reshape(-1, len(cols)).copy()
    return cols, data, header["meta"]

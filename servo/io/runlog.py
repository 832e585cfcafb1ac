"""Run logs in constant memory: rows streamed to a journal in blocks, finalised from it.

A run fills one block of rows at a time (:attr:`RunLog.data`, :attr:`RunLog.rows`).  A
full block is handed to a writer thread that appends it to ``<name>.journal`` (one JSON
header line, then raw little-endian float64 rows) and fsyncs it while the run fills the
next block; blocks that queue up during an fsync share the next one, and the loop waits
only when :attr:`RunLog.BUFFER_BYTES` of blocks wait for the disk.  A crash, a Ctrl-C or
a kill loses at most the rows not yet synced.  A failure to write the journal (disk full,
file size limit, the disk gone) is a :class:`JournalError`, a driver fault: the run stops
with the drive in its safe state.

:meth:`RunLog.finalise` (called by :meth:`RunLog.close`, which the context manager calls
on every exit path) streams the journal, in chunks, into ``<name>.npz`` and/or
``<name>.csv`` under temporary names, renames them into place and removes the journal: a
reader never sees a half-written NPZ or CSV, and a run of any length needs the same
memory.  The chunks also go to the caller's consumers (the run's summary and plots).
:func:`read_journal` recovers the rows of a journal a hard kill left behind;
:func:`finalise_journal` turns it into the NPZ and CSV.

NPZ: one float64 array per column (``t``, ``x``, ``u``...) plus ``meta`` (a JSON string).
CSV: a header row of column names with their units (``t [s]``, ``x [m]``: ``units``),
then one row per sample, ``%.17g`` (exact round trip).
"""
from __future__ import annotations

import json
import os
import queue
import signal
import threading
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from servo.errors import DriverError, RecordingError, first_line
from servo.io.atomic import atomic_write, naming

#: Rows per chunk when a journal is read back (~6 MB for 12 columns).
CHUNK_ROWS = 65536
#: Log formats a run can write.
FORMATS = ("npz", "csv")


class JournalError(DriverError):
    """The run log's journal could not be written: a fault that stops the run."""


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


def _rows_bytes(rows: np.ndarray):
    """The journal's bytes of ``rows`` (little-endian float64): on a little-endian host a
    view of the buffer itself, so that the write holds the interpreter lock only to start
    the system call (a ``tobytes()`` copy of a block held it ~0.1-0.3 ms, stalling the
    loop's thread that wanted it back)."""
    if np.little_endian and rows.dtype == np.float64 and rows.flags.c_contiguous:
        return memoryview(rows).cast("B")
    return rows.astype("<f8").tobytes()


class _Writer(threading.Thread):
    """Appends blocks to the journal and fsyncs each; returns the buffers for reuse.

    A block is ``(buffer, rows, first_row)``.  A block whose rows the journal already
    holds is skipped: a Ctrl-C that lands inside :meth:`RunLog._hand_over`, after the
    block was queued and before the log knew it, makes the closing flush queue it again.
    """

    def __init__(self, fh, free: queue.Queue):
        super().__init__(name="runlog-journal", daemon=True)
        self.fh, self.free = fh, free
        self.todo: queue.Queue = queue.Queue()
        self.error: OSError | None = None
        self.synced_rows = 0
        self.queued_rows = 0  # rows written or about to be: the next block's first row

    def run(self) -> None:
        while True:
            items = [self.todo.get()]
            while True:  # what queued up while the last fsync ran goes out with one fsync
                try:
                    items.append(self.todo.get_nowait())
                except queue.Empty:
                    break
            stop = items[-1] is None
            blocks = []
            for it in items:
                if it is not None and it[2] >= self.queued_rows:  # else already journalled
                    blocks.append(it)
                    self.queued_rows = it[2] + it[1]
            try:
                if self.error is None and blocks:
                    for buf, n, _ in blocks:
                        self.fh.write(_rows_bytes(buf[:n]))
                    self.fh.flush()
                    os.fsync(self.fh.fileno())
                    self.synced_rows += sum(n for _, n, _ in blocks)
            except OSError as exc:
                self.error = exc
            finally:
                for buf, _, _ in blocks:
                    self.free.put(buf)
                for _ in items:
                    self.todo.task_done()
            if stop:
                return


class RunLog:
    """A run log of ``columns``, journalled in blocks of ``block_rows`` rows.

    Fill rows of the current block in place (``data[rows]``), advance ``rows``, call
    :meth:`maybe_flush`; a caller may write up to ``headroom`` rows past ``block_rows``
    before it calls :meth:`maybe_flush` (the compiled loop writes a block of ticks per
    call).  ``formats``: which of ``npz``/``csv`` :meth:`finalise` writes; ``units``:
    column -> unit, for the CSV header.  Use as a
    context manager; :meth:`close` finalises whatever was recorded.
    """

    #: Bytes of blocks in memory (the one being filled and those waiting for the disk):
    #: a disk that stalls (an fsync of seconds under load) stalls the loop only once
    #: this much is waiting.  At least three blocks.
    BUFFER_BYTES = 8 << 20

    def __init__(self, out_dir: str | Path, name: str, columns, meta: dict | None = None, block_rows: int = 8192,
                 headroom: int = 1024, formats: Iterable[str] = FORMATS, units: dict[str, str] | None = None):  # fmt: skip
        self.dir = Path(out_dir)
        self.name = name
        self.columns = tuple(columns)
        self.meta = dict(meta or {})
        self.block_rows = int(block_rows)
        self.formats = tuple(formats)
        if not set(self.formats) <= set(FORMATS):
            raise ValueError(f"log formats are {FORMATS}, not {self.formats}")
        self.total = 0  # rows handed to the journal
        self.rows = 0  # rows in the current block
        self.closed = False
        self.finalised = False
        self._reported = False
        self.journal_path = self.dir / f"{name}.journal"
        self.dir.mkdir(parents=True, exist_ok=True)
        self._journal = open(self.journal_path, "wb")
        header = {"columns": self.columns, "units": dict(units or {}), "meta": self.meta}
        self._journal.write((json.dumps(header) + "\n").encode())
        self._journal.flush()
        os.fsync(self._journal.fileno())
        shape = (self.block_rows + headroom, len(self.columns))
        self.buffers = max(3, -(-self.BUFFER_BYTES // (8 * shape[0] * shape[1])))
        self._free: queue.Queue = queue.Queue()
        for _ in range(self.buffers - 1):
            self._free.put(np.full(shape, np.nan))  # written now (not calloc): no page faults in the loop
        self.data = np.full(shape, np.nan)
        self._writer = _Writer(self._journal, self._free)
        self._writer.start()

    @property
    def npz_path(self) -> Path:
        return self.dir / f"{self.name}.npz"

    @property
    def csv_path(self) -> Path:
        return self.dir / f"{self.name}.csv"

    @property
    def recorded_rows(self) -> int:
        """Rows recorded so far (handed to the journal and in the current block)."""
        return self.total + self.rows

    def maybe_flush(self) -> None:
        """Hand the current block to the journal when it is full."""
        if self.rows >= self.block_rows:
            self._hand_over()

    def flush(self, wait: bool = True) -> None:
        """Hand over what is recorded and wait until the journal holds it, synced
        (``wait=False``: do not wait; the writer journals it while the caller goes on, and
        :meth:`close` waits).  Raises :class:`JournalError` (once) if the journal could not
        be written."""
        if self.rows:
            self._hand_over()
        if wait:
            self._writer.todo.join()
        self._check()

    def _hand_over(self) -> None:
        # Ordered so that a KeyboardInterrupt between any two lines neither loses nor
        # doubles a block: queued but not yet reset, the closing flush queues the same
        # (buffer, rows, first row) again and the writer skips it.
        self._check()
        n, first = self.rows, self.total
        self._writer.todo.put((self.data, n, first))
        self.rows = 0
        self.total = first + n
        self.data = self._free.get()  # waits only if BUFFER_BYTES are waiting for the disk

    def _check(self) -> None:
        err = self._writer.error
        if err is not None and not self._reported:
            self._reported = True
            kept = journal_rows(self.journal_path)
            raise JournalError(f"run log: writing {self.journal_path} failed ({err.strerror or err}) after {kept} rows; "
                               "the run stopped with the drive at zero current")  # fmt: skip

    def _stop_writer(self) -> None:
        if self._writer.is_alive():
            self._writer.todo.put(None)
            self._writer.join()
        self._journal.close()

    def recorded(self) -> np.ndarray:
        """Every row recorded so far, read back from the journal (rows, columns).  This
        holds the whole log in memory: for tests and short runs."""
        self.flush()
        if self.finalised:
            return load_npz_rows(self.npz_path, self.columns) if "npz" in self.formats else np.loadtxt(
                self.csv_path, delimiter=",", skiprows=1, ndmin=2)  # fmt: skip
        return read_journal(self.journal_path)[1]

    def finalise(self, consumers: Iterable[Callable[[np.ndarray], None]] = ()) -> None:
        """Flush, stop the writer, then stream the journal into the NPZ/CSV (atomically)
        and remove it.  Each chunk of rows (at most :data:`CHUNK_ROWS`, in order) also
        goes to every consumer.  If the journal could not be written, what it holds is
        finalised, then the :class:`JournalError` is raised if it was not yet."""
        if self.finalised:
            return
        err = None
        if not self.closed:
            try:
                self.flush()
            except JournalError as exc:
                err = exc
            finally:
                self._stop_writer()
                self.closed = True
        with interrupts_deferred():  # a second Ctrl-C must not leave half the files
            try:
                finalise_journal(self.journal_path, self.formats, consumers, meta=self.meta)
            except OSError:
                if err is None:
                    raise
                # the disk that failed the journal (found after the last hand-over: the
                # loop ran ahead of the writer) fails its NPZ too: the journal's failure
                # is the fault to report, and the journal keeps what it holds
                raise err from None
        self.finalised = True
        if err is not None:
            raise err

    def close(self) -> None:
        """Finalise whatever was recorded (once); the journal stays if that fails."""
        self.finalise()

    def close_after_fault(self) -> None:
        """Finalise what was recorded when the run has already failed: a failure to do
        so (the disk that failed the run) leaves the journal in place and does not mask
        the fault that stopped the run."""
        try:
            self.finalise()
        except (OSError, DriverError):
            pass

    def __enter__(self) -> "RunLog":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.close_after_fault()


@contextmanager
def interrupts_deferred():
    """Hold SIGINT and SIGTERM back for the block (main thread only): a Ctrl-C during it
    is raised as :class:`KeyboardInterrupt` when the block ends, so the files it writes
    are complete.  A hard kill still leaves the journal."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    if caught:
        raise KeyboardInterrupt


#: Most bytes a journal's header line may take (a run's is well under 4 kB).
MAX_HEADER_BYTES = 1 << 20
#: Most columns a journal may declare (a run's log has about 15).
MAX_COLUMNS = 1024


class JournalFormatError(RecordingError):
    """A file given as a journal is not one (or not one this version wrote)."""


def journal_header(fh) -> tuple[tuple[str, ...], dict[str, str], dict]:
    """Columns, units and meta of the journal open (binary) as ``fh``, which is left at
    its first row.  The header is checked before anything is sized from it: one JSON
    line of at most :data:`MAX_HEADER_BYTES`, a table holding ``columns`` (1 to
    :data:`MAX_COLUMNS` distinct ASCII identifiers: they name files and NPZ members),
    ``units`` (column -> unit text, optional) and ``meta`` (a table, optional).  Raises
    :class:`JournalFormatError` naming what is wrong."""
    name = getattr(fh, "name", "journal")
    line = fh.readline(MAX_HEADER_BYTES + 1)

    def bad(what: str) -> JournalFormatError:
        return JournalFormatError(f"{name}: not a run-log journal: {what}")

    if not line.endswith(b"\n"):
        if len(line) > MAX_HEADER_BYTES:
            raise bad(f"no header line within its first {MAX_HEADER_BYTES} bytes")
        raise bad("no header line (the file ends before one)")
    try:
        header = json.loads(line)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise bad(f"its first line is not JSON ({first_line(exc)})") from None
    if not isinstance(header, dict):
        raise bad(f"its header is a JSON {type(header).__name__}, not a table")
    cols = header.get("columns")
    if not isinstance(cols, list) or not cols or len(cols) > MAX_COLUMNS:
        raise bad(f"its header's 'columns' must be a list of 1 to {MAX_COLUMNS} names")
    for c in cols:
        if not (isinstance(c, str) and c.isascii() and c.isidentifier()):
            raise bad(f"column name {c!r} is not an ASCII identifier (letters, digits, _)")
    dup = sorted({c for c in cols if cols.count(c) > 1})
    if dup:
        raise bad(f"column {dup[0]!r} is named twice")
    units = header.get("units", {})
    if not isinstance(units, dict) or not all(
            isinstance(u, str) and u.isascii() and u.isprintable() and "," not in u for u in units.values()):  # fmt: skip
        raise bad("its header's 'units' must be a table of column -> unit text (ASCII, no commas)")
    meta = header.get("meta", {})
    if not isinstance(meta, dict):
        raise bad("its header's 'meta' must be a table")
    return tuple(cols), {c: units[c] for c in cols if units.get(c)}, meta


def _journal_header(fh) -> tuple[tuple[str, ...], dict]:
    cols, _, meta = journal_header(fh)
    return cols, meta


def _csv_names(path) -> list[str]:
    """The CSV header of a journal's columns: ``name [unit]`` where a unit is known."""
    with open(path, "rb") as fh:
        cols, units, _ = journal_header(fh)
    return [f"{c} [{units[c]}]" if units.get(c) else c for c in cols]


def iter_journal(path: str | Path, chunk_rows: int = CHUNK_ROWS) -> Iterator[np.ndarray]:
    """The complete rows of a journal, in chunks of at most ``chunk_rows`` (rows, columns)."""
    with open(path, "rb") as fh:
        cols, _ = _journal_header(fh)
        width = len(cols)
        while True:
            raw = fh.read(8 * width * chunk_rows)
            whole = len(raw) - len(raw) % (8 * width)
            if whole == 0:
                return
            yield np.frombuffer(raw[:whole], dtype="<f8").reshape(-1, width)


def read_journal(path: str | Path) -> tuple[tuple[str, ...], np.ndarray, dict]:
    """Columns, complete rows and meta of a journal (e.g. one an interrupted run left)."""
    with open(path, "rb") as fh:
        cols, meta = _journal_header(fh)
    chunks = list(iter_journal(path))
    data = np.concatenate(chunks) if chunks else np.zeros((0, len(cols)))
    return cols, data, meta


def journal_rows(path: str | Path) -> int:
    """Complete rows in a journal."""
    with open(path, "rb") as fh:
        cols, _ = _journal_header(fh)
        body = os.fstat(fh.fileno()).st_size - fh.tell()
    return body // (8 * len(cols))


def finalise_journal(path: str | Path, formats: Iterable[str] = FORMATS,
                     consumers: Iterable[Callable[[np.ndarray], None]] = (), meta: dict | None = None) -> list[Path]:  # fmt: skip
    """Write ``<name>.npz`` and/or ``<name>.csv`` beside the journal ``path`` from its
    complete rows, in one streaming pass (plus one pass over per-column temporaries for
    the NPZ), atomically; then remove the journal.  Returns the files written."""
    path = Path(path)
    with open(path, "rb") as fh:
        cols, jmeta = _journal_header(fh)
    meta = dict(jmeta if meta is None else meta)
    meta["rows"] = journal_rows(path)
    stem = path.with_suffix("")
    formats = tuple(formats)
    consumers = tuple(consumers)
    written = []
    tmp_cols = [stem.with_name(f".{stem.name}.{c}.col") for c in cols]
    csv_tmp = stem.with_name(f".{stem.name}.csv.tmp")
    with naming(stem.with_suffix(".npz" if "npz" in formats else ".csv")):  # a full disk's error says where
        try:
            col_fh = [open(p, "wb") for p in tmp_cols] if "npz" in formats else []
            csv_fh = open(csv_tmp, "w", encoding="ascii") if "csv" in formats else None
            try:
                if csv_fh:
                    csv_fh.write(",".join(_csv_names(path)) + "\n")
                for chunk in iter_journal(path):
                    for i, f in enumerate(col_fh):
                        f.write(np.ascontiguousarray(chunk[:, i]).tobytes())
                    if csv_fh:
                        np.savetxt(csv_fh, chunk, fmt="%.17g", delimiter=",")
                    for consume in consumers:
                        consume(chunk)
            finally:
                for f in col_fh:
                    f.close()
                if csv_fh:
                    csv_fh.close()
            if "npz" in formats:
                atomic_write(stem.with_suffix(".npz"), lambda tmp: _zip_columns(tmp, cols, tmp_cols, meta))
                written.append(stem.with_suffix(".npz"))
            if csv_fh:
                os.replace(csv_tmp, stem.with_suffix(".csv"))
                written.append(stem.with_suffix(".csv"))
        finally:
            for p in [*tmp_cols, csv_tmp]:
                if p.exists():
                    p.unlink()
    path.unlink()
    return written


def _zip_columns(dest, cols, col_files, meta: dict) -> None:
    """An NPZ (``np.load`` reads it like ``np.savez``'s) of the column files, streamed."""
    with zipfile.ZipFile(dest, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for c, p in zip(cols, col_files):
            n = os.path.getsize(p) // 8
            with zf.open(f"{c}.npy", "w", force_zip64=True) as out, open(p, "rb") as src:
                np.lib.format.write_array_header_1_0(out, {"descr": "<f8", "fortran_order": False, "shape": (n,)})
                while block := src.read(1 << 22):
                    out.write(block)
        with zf.open("meta.npy", "w") as out:
            np.lib.format.write_array(out, np.array(json.dumps(meta)))


def load_npz_rows(path: str | Path, columns) -> np.ndarray:
    """The rows of a finalised NPZ log as one (rows, columns) array."""
    with np.load(path) as z:
        return np.column_stack([z[c] for c in columns])

"""Named columns from the files labs have: delimited text, NPZ, MATLAB v4-v7 and v7.3, HDF5.

:func:`read_table` returns ``{name: array}``; :mod:`servo.io.recording` maps the names to
the roles ``t, u, x, v, r`` and validates.  Every problem is one
:class:`~servo.errors.RecordingError` line naming the file and, for text, the line.

* **Delimited text** (``.csv``, ``.tsv``, ``.txt``, ``.dat``): a header row naming the
  columns, after any blank lines and ``#`` comment lines; the delimiter is found from the
  header and the first data row (``,`` ``;`` tab ``|`` or runs of spaces); a byte-order
  mark (UTF-8 or UTF-16, as spreadsheets write) is not part of the first name; a decimal
  comma is read as a point when the delimiter is not a comma; quotes around names are
  dropped and a unit in brackets after a name, ``x [m]`` or ``x (m)``, is split off
  (kept in the table's ``units``).  The numbers are parsed by ``numpy.loadtxt`` straight
  from the file; only when that fails is the file scanned row by row, to name the first
  bad line.
* **NPZ**: one array per name (no pickles).
* **MATLAB** ``.mat``: v4-v7 through ``scipy.io.loadmat``, v7.3 (an HDF5 file) through
  ``h5py``; fields of structs are named ``struct.field``; text, cell and empty
  variables are left out.
* **HDF5** (``.h5``, ``.hdf5``): every numeric dataset, named by its path without the
  leading ``/`` (``group/dataset``).

Memory follows what a tool asks for, never what the file holds: only the named columns
a tool reads are loaded from NPZ, MATLAB and HDF5 files (an unused column of any size
costs nothing), each checked against :data:`MAX_SAMPLES` from its declared shape before
it is read; text is parsed whole, each line at most :data:`MAX_LINE_CHARS` characters
and the table at most :data:`MAX_TEXT_VALUES` values, its lines counted in chunks of
:data:`COUNT_CHUNK` before a value is parsed (a file beyond the budget is refused
whatever its size, in the memory of one chunk); and a compressed MATLAB variable is
inflated to at most :data:`MAX_INFLATED_BYTES` (docs/robustness.md).
"""
from __future__ import annotations

import csv
import io
import re
import warnings
from pathlib import Path

import numpy as np

from servo.errors import RecordingError, first_line

#: Most samples a column may hold (11 minutes at 50 kHz; 268 MB as float64).
MAX_SAMPLES = 1 << 25
#: Most characters a line of a text recording may hold (a header of ~5000 names).
MAX_LINE_CHARS = 1 << 16
#: Most values a text recording may hold, all columns (every one is parsed; 1.07 GB).
MAX_TEXT_VALUES = 4 * MAX_SAMPLES
#: Most bytes a compressed MATLAB variable may inflate to (any column of MAX_SAMPLES).
MAX_INFLATED_BYTES = 8 * MAX_SAMPLES + (1 << 20)

TEXT_SUFFIXES = (".csv", ".tsv", ".txt", ".dat")
HDF5_SUFFIXES = (".h5", ".hdf5", ".he5")
DELIMITERS = (",", ";", "\t", "|")
_UNIT = re.compile(r"^(?P<name>.*?)\s*(?:\[(?P<u1>[^\]]*)\]|\((?P<u2>[^)]*)\))$")


class Table(dict):
    """``{name: array}`` of the columns read, with ``names`` (every column of the file,
    read or not), ``units`` (``{name: unit}``, from text headers) and the ``format`` it
    was read from."""

    def __init__(self, data=(), units: dict | None = None, format: str = "", names=None):
        super().__init__(data)
        self.units = dict(units or {})
        self.format = format
        self.names = list(self if names is None else names)


def read_table(path: str | Path, wanted=None) -> Table:
    """The named columns of ``path`` (format from the suffix; see the module docstring):
    those in ``wanted`` (None: all), each checked against :data:`MAX_SAMPLES` before it
    is read; ``Table.names`` lists every column of the file."""
    path = Path(path)
    suffix = path.suffix.lower()
    wanted = None if wanted is None else set(wanted)
    try:
        if suffix in TEXT_SUFFIXES:
            return _read_text(path)  # parsed whole: a row is checked field by field
        if suffix == ".npz":
            return _read_npz(path, wanted)
        if suffix == ".mat":
            return _read_mat(path, wanted)
        if suffix in HDF5_SUFFIXES:
            return _read_hdf5(path, sep="/", fmt="hdf5", wanted=wanted)
    except RecordingError:
        raise
    except FileNotFoundError:
        raise RecordingError(f"recording: no such file: {path}") from None
    except IsADirectoryError:
        raise RecordingError(f"recording: {path} is a directory, not a file") from None
    except Exception as exc:  # corrupt or foreign file: one line, whatever the reader raised
        what = suffix[1:].upper() or "a recording"
        raise RecordingError(f"recording: cannot read {path} as {what}: {first_line(exc)}") from None
    known = ", ".join(TEXT_SUFFIXES + (".npz", ".mat") + HDF5_SUFFIXES)
    raise RecordingError(f"recording: {path}: unknown format {suffix!r} (use {known}; export spreadsheets as CSV)")


def _check_size(path: Path, name: str, shape) -> None:
    """Refuse a column whose declared shape holds more than :data:`MAX_SAMPLES` values."""
    size = int(np.prod(shape, dtype=object))
    if size > MAX_SAMPLES:
        raise RecordingError(f"recording: {path}: column {name!r} holds {size} values ({'x'.join(map(str, shape))}), "
                             f"more than the {MAX_SAMPLES} a column may hold")  # fmt: skip


def _read_npz(path: Path, wanted) -> Table:
    out = {}
    with np.load(path, allow_pickle=False) as z:
        members = set(z.zip.namelist())
        for k in z.files:
            if (wanted is not None and k not in wanted) or f"{k}.npy" not in members:  # (not an array: no column)
                continue
            with z.zip.open(f"{k}.npy") as f:  # its header: the shape, before the data is read
                major, _ = np.lib.format.read_magic(f)
                read = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
                shape, _, _ = read(f)
            _check_size(path, k, shape)
            out[k] = np.asarray(z[k])
        return Table(out, format="npz", names=[k for k in z.files if f"{k}.npy" in members])


# -- delimited text ------------------------------------------------------------------


def _lines(fh, path: Path, lineno: int, max_rows: int | None = None, ncol: int = 0):
    """The lines of ``fh`` from line ``lineno + 1`` on, each at most :data:`MAX_LINE_CHARS`
    characters (a longer one is refused, never read whole); and, given ``max_rows``, at
    most that many rows that are not comments (more are refused: the table's budget)."""
    rows = 0
    while line := fh.readline(MAX_LINE_CHARS + 1):
        lineno += 1
        if len(line) > MAX_LINE_CHARS:
            raise RecordingError(f"recording: {path} line {lineno}: longer than {MAX_LINE_CHARS} characters")
        if max_rows is not None and not _is_comment(line):
            rows += 1
            if rows > max_rows:
                raise _too_many_rows(path, f"more than {max_rows} rows", max_rows, ncol)
        yield line


#: Bytes (UTF-8) or characters (UTF-16) read at a time while a text recording's lines are counted.
COUNT_CHUNK = 1 << 20


def _too_many_rows(path: Path, what: str, max_rows: int, ncol: int) -> RecordingError:
    return RecordingError(f"recording: {path}: {what}, more than the {max_rows} rows of {ncol} columns a text recording "
                          f"may hold ({MAX_TEXT_VALUES} values); convert it to NPZ or HDF5")  # fmt: skip


def _check_line_count(path: Path, enc: str, header_lines: int, max_rows: int, ncol: int) -> None:
    """Refuse a text recording with more than ``max_rows`` lines after its first
    ``header_lines``, counted in chunks of :data:`COUNT_CHUNK` before anything is parsed:
    memory stays one chunk whatever the file's size, and the scan stops at the limit.
    (Comment and blank lines count too: the count is an upper bound of the rows.)"""
    limit = header_lines + max_rows
    newline, mode = ("\n", "r") if enc == "utf-16" else (b"\n", "rb")  # a UTF-8 sequence never holds byte 0x0A
    lines, last = 0, newline
    with open(path, mode, **({"encoding": enc, "newline": ""} if mode == "r" else {})) as fh:
        while chunk := fh.read(COUNT_CHUNK):
            lines += chunk.count(newline)
            last = chunk[-1:]
            if lines > limit:
                break
    lines += last != newline  # a last line without its newline
    if lines > limit:
        raise _too_many_rows(path, f"at least {lines - header_lines} lines after its header", max_rows, ncol)


def _encoding(path: Path) -> str:
    with open(path, "rb") as fh:
        head = fh.read(4)
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "utf-16"  # the BOM gives the byte order and is dropped
    return "utf-8-sig"  # -sig: a UTF-8 byte-order mark is not part of the header


def _is_comment(line: str) -> bool:
    s = line.strip()
    return not s or s.startswith("#")


def _split(line: str, delim: str | None) -> list[str]:
    if delim is None:
        return line.split()
    return next(csv.reader([line], delimiter=delim))


def _delimiter(header: str, first: str | None) -> str | None:
    """The delimiter that splits the header and the first data row alike (None: spaces)."""
    for d in DELIMITERS:
        n = len(_split(header, d))
        if n > 1 and (first is None or len(_split(first, d)) == n):
            return d
    for d in DELIMITERS:  # the data row may be ragged: let the row check name it
        if len(_split(header, d)) > 1:
            return d
    return None


def _names(fields: list[str], path: Path) -> tuple[list[str], dict]:
    names, units = [], {}
    for f in fields:
        f = f.strip().strip('"').strip("'").strip()
        m = _UNIT.match(f)
        if m and m.group("name"):
            f, unit = m.group("name").strip(), (m.group("u1") if m.group("u1") is not None else m.group("u2")).strip()
            units[f] = unit
        names.append(f)
    if not names or any(not n for n in names):
        raise RecordingError(f"recording: {path}: the first row must name every column")
    if all(_number(n) for n in names):
        raise RecordingError(f"recording: {path}: no header row: the first row must name the columns (e.g. t,u,x)")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise RecordingError(f"recording: {path}: column {dup[0]!r} is named twice in the header")
    return names, units


def _number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _read_text(path: Path) -> Table:
    enc = _encoding(path)
    with open(path, encoding=enc, newline="") as fh:
        lineno, header, comment = 0, None, None
        for line in _lines(fh, path, 0):
            lineno += 1
            if not _is_comment(line):
                header = line.rstrip("\r\n")
                break
            if line.strip():
                comment = line.strip()[1:].strip()
        if header is None:
            raise RecordingError(f"recording: {path} is empty")
        start = fh.tell()
        first = None
        for line in _lines(fh, path, lineno):
            if not _is_comment(line):
                first = line.rstrip("\r\n")
                break
        delim = _delimiter(header, first)
        fields = _split(header, delim)
        if comment is not None and all(_number(f) for f in fields if f.strip()):
            # a header written as a comment ("# t u x"), then numbers from the first line on
            cdelim = _delimiter(comment, header)
            if len(_split(comment, cdelim)) == len(fields):
                fields, start, lineno = _split(comment, cdelim), None, lineno - 1
        trailing = len(fields) > 1 and not fields[-1].strip()  # "t,u,x," as some exporters write
        names, units = _names(fields[:-1] if trailing else fields, path)
        if first is None and start is not None:
            raise RecordingError(f"recording: {path}: a header row ({', '.join(names)}) and no rows of numbers")
        comma = delim not in (",", None) and first is not None and "," in first
        if start is None:
            fh.seek(0)
            for _ in range(lineno):
                fh.readline(MAX_LINE_CHARS + 1)  # lines read once already: within the bound
        else:
            fh.seek(start)
        ncol = len(names)
        max_rows = max(1, min(MAX_SAMPLES, MAX_TEXT_VALUES // ncol))  # every column is read: a row is checked whole
        _check_line_count(path, enc, lineno, max_rows, ncol)  # before a value is parsed: refusal costs one chunk
        lines = _lines(fh, path, lineno, max_rows, ncol)  # (loadtxt's own max_rows would allocate them all;
        # the rows are also counted as they are read: a line ending the count missed, a lone CR, is bounded too)
        src = (line.replace(",", ".") for line in lines) if comma else lines
        try:
            with warnings.catch_warnings():  # "input contained no data": said below in one line
                warnings.simplefilter("ignore", UserWarning)
                data = np.loadtxt(src, delimiter=delim, comments="#", quotechar='"', ndmin=2, dtype=float,
                                  usecols=range(ncol) if trailing else None)  # fmt: skip
        except ValueError:
            data = None
    if data is None or (data.size and data.shape[1] != ncol):
        _first_bad_line(path, enc, lineno, delim, comma, ncol, trailing)
        raise RecordingError(f"recording: {path}: not a table of numbers with {ncol} columns")
    if data.size == 0:
        raise RecordingError(f"recording: {path}: a header row ({', '.join(names)}) and no rows of numbers")
    data = data.reshape(-1, ncol)
    return Table({n: data[:, i] for i, n in enumerate(names)}, units, format="text")


def _first_bad_line(path, enc, header_line, delim, comma, ncol, trailing=False) -> None:
    """Raise the error of the first line that is not ``ncol`` numbers (then an empty
    field if ``trailing``): the slow path, taken only when ``numpy.loadtxt`` failed."""
    with open(path, encoding=enc, newline="") as fh:
        for lineno, line in enumerate(_lines(fh, path, 0), start=1):
            if lineno <= header_line or _is_comment(line):
                continue
            text = line.split("#", 1)[0].rstrip("\r\n")
            fields = _split(text.replace(",", ".") if comma else text, delim)
            if len(fields) != ncol + trailing:
                raise RecordingError(f"recording: {path} line {lineno}: {len(fields)} fields, the header has "
                                     f"{ncol + trailing}")  # fmt: skip
            for f in fields[:ncol]:
                if not _number(f.strip()):
                    hint = " (a decimal comma with a comma delimiter?)" if delim == "," else ""
                    raise RecordingError(f"recording: {path} line {lineno}: not a number: {f.strip()!r}{hint}")


# -- MATLAB and HDF5 -----------------------------------------------------------------


#: the signature an HDF5 file starts with, at offset 0 or after a user block of 512 * 2**k bytes
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _is_hdf5(path: Path) -> bool:
    """Whether ``path`` is an HDF5 file (MAT v7.3 is one, after a 512-byte user block):
    its signature at offset 0, 512, 1024, 2048...  (where ``H5Fis_hdf5`` looks), read
    without importing h5py, which a MAT v5 file (the common case) does not need."""
    with open(path, "rb") as fh:
        offset = 0
        while True:
            fh.seek(offset)
            head = fh.read(len(HDF5_SIGNATURE))
            if len(head) < len(HDF5_SIGNATURE):
                return False
            if head == HDF5_SIGNATURE:
                return True
            offset = 512 if offset == 0 else 2 * offset


def _read_mat(path: Path, wanted=None) -> Table:
    if _is_hdf5(path):
        return _read_hdf5(path, sep=".", fmt="mat v7.3", wanted=wanted)
    from scipy.io import loadmat, whosmat

    raw = path.read_bytes()
    every = None
    if raw[124:126] == b"\x00\x01" or raw[124:126] == b"\x01\x00":  # v5-v7: its tags first
        raw, every = _mat5_select(raw, wanted)  # an unused variable is never inflated
        _check_mat5_tags(raw)
    listed = whosmat(io.BytesIO(raw))  # names, shapes and classes from the headers
    top = [name for name, _, _ in listed]
    if wanted is not None:  # "struct.field" is read through its struct
        top = [name for name in top if name in wanted or any(w.startswith(name + ".") for w in wanted)]
    for name, shape, _ in listed:
        if name in top:
            _check_size(path, name, shape)
    out: dict = {}
    if top:
        _flatten_mat(loadmat(io.BytesIO(raw), simplify_cells=True, variable_names=top), "", out)
    names = [name for name, _, cls in listed if cls != "struct"] + [n for n in out if "." in n]
    names += [n for n in every or () if n not in names and not any(m.startswith(n + ".") for m in names)]
    return Table(out if wanted is None else {k: v for k, v in out.items() if k in wanted}, format="mat", names=names)


def _mat5_select(raw: bytes, wanted) -> tuple[bytes, list[str]]:
    """A MAT v5 file's bytes with only the top-level variables ``wanted`` names (all when
    None; ``s`` for ``s.field``; a variable whose name cannot be read is kept, for the
    checks to refuse), and the names of all.  A compressed variable's name is read from
    its first inflated bytes: a variable that is not wanted is never inflated."""
    import zlib

    order = "<" if raw[126:128] == b"IM" else ">"
    keep, names, i = [raw[:128]], [], 128
    tops = None if wanted is None else {w.split(".")[0] for w in wanted}
    while i + 8 <= len(raw):
        mtype, size = (int(v) for v in np.frombuffer(raw, f"{order}u4", 2, i))
        if mtype >> 16:  # a small element at the top level: not a variable; the tag check names it
            keep.append(raw[i:])
            break
        end = i + 8 + (size if mtype == _MI_COMPRESSED else (size + 7) // 8 * 8)
        body = raw[i + 8:min(end, len(raw))]
        if mtype == _MI_COMPRESSED:
            try:
                body = zlib.decompressobj().decompress(body, 4096)[8:]  # past the inner matrix tag
            except zlib.error:
                body = b""
        name = _mat5_name(body, order) if mtype in (_MI_MATRIX, _MI_COMPRESSED) else None
        if name is not None:
            names.append(name)
        if tops is None or name is None or name in tops:
            keep.append(raw[i:end])
        i = end
    return b"".join(keep), names


def _mat5_name(body: bytes, order: str) -> str | None:
    """The name of a MAT v5 matrix from the start of its body (array flags, dimensions,
    name sub-elements), or None where they are not whole or not what the format says."""
    o = 0
    for _ in range(3):
        if o + 8 > len(body):
            return None
        word, size = (int(v) for v in np.frombuffer(body, f"{order}u4", 2, o))
        if word >> 16:
            data, o = body[o + 4:o + 4 + (word >> 16)], o + 8
        else:
            data, o = body[o + 8:o + 8 + size], o + 8 + (size + 7) // 8 * 8
    try:
        return data.decode("ascii") or None
    except UnicodeDecodeError:
        return None


_MAT5_TYPES = frozenset(range(1, 19)) - {8, 10, 11}  # miINT8 .. miUTF32 (8, 10, 11 unused)
_MI_MATRIX, _MI_COMPRESSED = 14, 15


def _check_mat5_tags(raw: bytes) -> None:
    """Walk a MAT v5 file's data elements and refuse one whose type tag or length is not
    the format's: scipy's compiled reader indexes a table by the tag and crashes the
    process on an unknown one (a corrupt byte), where it should raise.  Matrices are
    walked into (cells and structs are matrices of matrices); compressed elements are
    inflated and walked."""
    import zlib

    order = "<" if raw[126:128] == b"IM" else ">"

    def walk(buf: bytes, start: int, end: int, top: bool) -> None:
        i = start
        while i + 8 <= end:
            word, size = np.frombuffer(buf, f"{order}u4", 2, i)
            word, size = int(word), int(size)
            if word >> 16:  # small data element: the size in the upper half, data in 4 bytes
                mtype, size, body, step = word & 0xFFFF, word >> 16, i + 4, 8
                if size > 4:
                    raise ValueError(f"a small data element of {size} bytes at byte {i}")
            else:
                mtype, body = word, i + 8
                step = 8 + (size if mtype == _MI_COMPRESSED else (size + 7) // 8 * 8)
            if mtype not in _MAT5_TYPES or (mtype == _MI_COMPRESSED and not top):
                raise ValueError(f"unknown data type {mtype} at byte {i}")
            if body + size > end:
                raise ValueError(f"an element at byte {i} runs past the end of the file")
            if mtype == _MI_COMPRESSED:
                inflate = zlib.decompressobj()
                inner = inflate.decompress(buf[body:body + size], MAX_INFLATED_BYTES)
                if inflate.unconsumed_tail:
                    raise ValueError(f"the compressed variable at byte {i} inflates beyond {MAX_INFLATED_BYTES} bytes, "
                                     "the most a variable may hold")  # fmt: skip
                walk(inner, 0, len(inner), top=False)
            elif mtype == _MI_MATRIX:
                walk(buf, body, body + size, top=False)
            i += step

    walk(raw, 128, len(raw), top=True)


def _flatten_mat(obj: dict, prefix: str, out: dict) -> None:
    for k, v in obj.items():
        if k.startswith("__"):
            continue
        name = prefix + k
        if isinstance(v, dict):
            _flatten_mat(v, name + ".", out)
            continue
        a = np.asarray(v)
        if a.dtype.kind in "fiub" and a.size:
            out[name] = a


def _read_hdf5(path: Path, sep: str, fmt: str, wanted=None) -> Table:
    import h5py

    out: dict = {}
    names: list = []
    with h5py.File(path, "r") as f:

        def visit(group, prefix):
            for key, item in group.items():
                if key.startswith("#"):  # MATLAB's #refs# and #subsystem#
                    continue
                name = prefix + key
                if isinstance(item, h5py.Group):
                    visit(item, name + sep)
                    continue
                cls = item.attrs.get("MATLAB_class", b"")
                cls = cls.decode() if isinstance(cls, bytes) else str(cls)
                if cls in ("char", "cell") or item.attrs.get("MATLAB_empty", 0):
                    continue
                if item.dtype.kind not in "fiub" or item.size == 0:
                    continue
                names.append(name)
                if wanted is None or name in wanted:
                    _check_size(path, name, item.shape)  # its declared shape, before a byte is read
                    out[name] = np.asarray(item[()])  # MATLAB's column-major order is moot for vectors

        visit(f, "")
    return Table(out, format=fmt, names=names)


__all__ = ["Table", "read_table"]

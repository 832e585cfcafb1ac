"""Recordings as labs have them: delimited text of every common dialect, MATLAB v5 with
structs, MATLAB v7.3 (HDF5) as MATLAB writes it, plain HDF5; and every malformed file
one error line (fuzzed)."""
from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servo.errors import RecordingError
from servo.io.recording import load_recording

N = 64
T = np.arange(N) * 1e-3
U = np.sin(40 * T) * 1e-2
X = np.cos(40 * T) * 1e-4
V = -40 * np.sin(40 * T) * 1e-4


def _text(sep: str, header=("t", "u", "x", "v"), decimal=".", eol="\n", pre="") -> str:
    lines = [sep.join(header)]
    for row in zip(T, U, X, V):
        lines.append(sep.join(repr(float(v)).replace(".", decimal) for v in row))
    return pre + eol.join(lines) + eol


def _same(rec, v=True):
    np.testing.assert_array_equal(rec.t, T)
    np.testing.assert_array_equal(rec.u, U)
    np.testing.assert_array_equal(rec.x, X)
    if v:
        np.testing.assert_array_equal(rec.v, V)


@pytest.mark.parametrize(
    "name,content",
    [
        ("semicolon.csv", _text(";")),
        ("european.csv", _text(";", decimal=",")),  # decimal comma, as a German Excel writes
        ("tabs.tsv", _text("\t")),
        ("spaces.dat", _text("   ")),
        ("pipes.txt", _text("|")),
        ("crlf.csv", _text(",", eol="\r\n")),
        ("comments.csv", _text(",", pre="# exported by scope 1234\n#\n\n")),
        ("commented_header.txt", "# rig 3, 2024-05-01\n# t u x v\n" + _text(" ").split("\n", 1)[1]),
        ("quoted.csv", _text(",", header=('"t"', '"u"', '"x"', '"v"'))),
        ("trailing.csv", _text(",", header=("t", "u", "x", "v", "")).replace("\n", ",\n").replace(",,\n", ",\n")),
    ],
)
def test_delimited_text_dialects(tmp_path, name, content):
    p = tmp_path / name
    p.write_text(content)
    _same(load_recording(p))


def test_byte_order_marks_and_utf16_as_spreadsheets_write(tmp_path):
    p = tmp_path / "bom8.csv"
    p.write_bytes(b"\xef\xbb\xbf" + _text(",").encode())
    _same(load_recording(p))
    p = tmp_path / "unicode.txt"  # Excel's "Unicode text": UTF-16 LE with a BOM, tab-separated
    p.write_bytes(_text("\t", eol="\r\n").encode("utf-16"))
    _same(load_recording(p))


def test_units_in_the_header_are_split_off_and_kept(tmp_path):
    p = tmp_path / "units.csv"
    p.write_text(_text(",", header=("t [s]", "u (A)", "x [m]", "v [m/s]")))
    rec = load_recording(p)
    _same(rec)
    assert rec.meta["units"] == {"t": "s", "u": "A", "x": "m", "v": "m/s"}


def test_mat_v5_with_a_struct_and_a_scale_variable(tmp_path):
    from scipy.io import savemat

    p = tmp_path / "v5.mat"
    savemat(p, {"run": {"time": T, "cur": U / 2, "pos": X[:, None]}, "gain": 2.0, "note": "rig 3"})
    rec = load_recording(p, columns={"t": "run.time", "u": "run.cur", "x": "run.pos"}, scale={"u": "gain"})
    _same(rec, v=False)


def _write_mat73(path, variables: dict, strings: dict = (), struct: dict | None = None):
    """A MAT v7.3 file laid out as MATLAB writes one: a 512-byte user block with the MAT
    header text, each variable a dataset with ``MATLAB_class``, vectors stored
    transposed (``(1, n)`` for a column), text as uint16 ``char``, a struct a group."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for k, v in variables.items():
            d = f.create_dataset(k, data=np.atleast_2d(np.asarray(v, float)))
            d.attrs["MATLAB_class"] = np.bytes_("double")
        for k, s in dict(strings).items():
            d = f.create_dataset(k, data=np.frombuffer(s.encode("utf-16-le"), np.uint16)[:, None])
            d.attrs["MATLAB_class"] = np.bytes_("char")
        if struct:
            g = f.create_group(struct["name"])
            g.attrs["MATLAB_class"] = np.bytes_("struct")
            for k, v in struct["fields"].items():
                d = g.create_dataset(k, data=np.atleast_2d(np.asarray(v, float)))
                d.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon May  6 10:00:00 2024 HDF5 schema 1.00 ."
        fh.write(text.ljust(116) + b" " * 8 + b"\x00\x02IM")  # text, subsystem offset, version 0x0200, endian


def test_mat_v73_through_h5py(tmp_path):
    p = tmp_path / "v73.mat"
    _write_mat73(p, {"t": T, "vir": U / 2, "qm": X, "gtau": 2.0}, strings={"operator": "ab"},
                 struct={"name": "extra", "fields": {"v": V}})  # fmt: skip
    from scipy.io import loadmat

    with pytest.raises(NotImplementedError):  # what scipy alone says of such a file
        loadmat(p)
    rec = load_recording(p, columns={"u": "vir", "x": "qm", "v": "extra.v"}, scale={"u": "gtau"})
    _same(rec)
    assert rec.meta["format"] == "mat v7.3"
    with pytest.raises(RecordingError, match="has no column 'operator'"):  # text is not a column
        load_recording(p, columns={"u": "operator", "x": "qm"})


def test_plain_hdf5_by_dataset_path(tmp_path):
    import h5py

    p = tmp_path / "scope.h5"
    with h5py.File(p, "w") as f:
        f["meta/rate"] = 1000.0
        g = f.create_group("ch")
        g["time"], g["current"], g["position"] = T, U, X
    rec = load_recording(p, columns={"t": "ch/time", "u": "ch/current", "x": "ch/position"})
    _same(rec, v=False)


@pytest.mark.parametrize(
    "content,needle",
    [
        ("# only a comment\n\n", "is empty"),
        ("", "is empty"),
        ("1,2,3\n4,5,6\n", "no header row"),
        ("t,u,t\n1,2,3\n", "column 't' is named twice"),
        ("t,,x\n1,2,3\n", "must name every column"),
        ("# c\nt,u,x\n0,1,2\n# c\n1,2\n", "line 5: 2 fields, the header has 3"),
        ("t;u;x\n0;1;2\n1;x2;3\n", "line 3: not a number: 'x2'"),
        ("t,u,x\n0,1.5,2\n1,2,3,4\n", "line 3: 4 fields"),
        ("t,u,x\n0,\"1,5\",2\n", "decimal comma"),
    ],
)
def test_malformed_text_is_one_line_naming_the_line(tmp_path, content, needle):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    with pytest.raises(RecordingError, match=needle) as e:
        load_recording(p)
    assert "\n" not in str(e.value)


def _one_line_or_loaded(path):
    try:
        load_recording(path, min_samples=2)
    except RecordingError as exc:
        msg = str(exc)
        assert msg.startswith("recording") and "\n" not in msg and len(msg) < 600, msg


FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(edits=st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 6), st.sampled_from(
    list(",;\t |.-+eE#\"'\n\r0123456789naif") + ["\ufeff", "\x00", "\u00e9", "1e999", "nan", "inf"])), max_size=8),
       sep=st.sampled_from([",", ";", "\t", " "]))  # fmt: skip
def test_fuzzed_text_loads_or_is_one_error_line(tmp_path, edits, sep):
    text = _text(sep)[:1500]
    for pos, cut, s in edits:
        pos %= len(text) + 1
        text = text[:pos] + s + text[pos + cut :]
    p = tmp_path / "fuzz.csv"
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    _one_line_or_loaded(p)


@FUZZ
@given(data=st.data())
def test_fuzzed_binary_files_load_or_are_one_error_line(tmp_path, data):
    kind = data.draw(st.sampled_from(["npz", "mat5", "mat73", "h5"]))
    src = tmp_path / f"src.{kind}"
    if not src.exists():
        if kind == "npz":
            np.savez(src, t=T, u=U, x=X)
        elif kind == "mat5":
            from scipy.io import savemat

            savemat(src, {"t": T, "u": U, "x": X})
        elif kind == "mat73":
            _write_mat73(src, {"t": T, "u": U, "x": X})
        else:
            import h5py

            with h5py.File(src, "w") as f:
                f["t"], f["u"], f["x"] = T, U, X
    raw = bytearray(src.read_bytes())
    cut = data.draw(st.integers(0, len(raw)))
    flips = data.draw(st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(0, 255)), max_size=6))
    for i, b in flips:
        raw[i] = b
    if data.draw(st.booleans()):
        raw = raw[:cut]
    suffix = {"mat5": ".mat", "mat73": ".mat", "h5": ".h5", "npz": ".npz"}[kind]
    p = tmp_path / f"fuzz{suffix}"
    p.write_bytes(bytes(raw))
    _one_line_or_loaded(p)


def test_an_npz_whose_member_name_is_corrupt_is_one_short_line(tmp_path):
    """numpy's zip reader quotes the whole raw member header when a name in it differs
    from the directory's; the error line keeps its start only (found by the fuzz above)."""
    src = tmp_path / "src.npz"
    np.savez(src, t=T, u=U, x=X)
    raw = bytearray(src.read_bytes())
    raw[27] = 1  # inside the first local file header's name
    p = tmp_path / "bad.npz"
    p.write_bytes(bytes(raw))
    with pytest.raises(RecordingError) as err:
        load_recording(p, min_samples=2)
    msg = str(err.value)
    assert msg.startswith("recording: cannot read") and "\n" not in msg and len(msg) < 600
    assert str(p) in msg


def test_a_mat_file_with_an_unknown_type_tag_is_one_line_not_a_crash(tmp_path):
    """scipy's compiled MAT v5 reader crashes the process (SIGSEGV) on a data type tag it
    does not know; the tags are checked first (found by the fuzz above)."""
    from scipy.io import savemat

    src = tmp_path / "src.mat"
    savemat(src, {"t": T, "u": U, "x": X})
    raw = bytearray(src.read_bytes())
    real_part = np.array([9, 8 * N], "<u4").tobytes()  # miDOUBLE, N doubles
    i = raw.find(real_part, raw.find(real_part) + 1)  # the second variable's values
    assert i > 0
    raw[i] = 22
    p = tmp_path / "bad.mat"
    p.write_bytes(bytes(raw))
    with pytest.raises(RecordingError, match=r"unknown data type 22 at byte"):
        load_recording(p, min_samples=2)


def test_a_large_csv_is_parsed_by_numpy_not_row_by_row(tmp_path, monkeypatch):
    """200 000 rows: read through numpy.loadtxt in one call (the row-by-row scan only runs
    to name a bad line), values exact."""
    import servo.io.tables as tables

    n = 200_000
    t = np.arange(n) * 1e-4
    data = np.column_stack([t, np.sin(t), np.cos(t)])
    buf = io.StringIO()
    buf.write("t,u,x\n")
    np.savetxt(buf, data, fmt="%.17g", delimiter=",")
    p = tmp_path / "big.csv"
    p.write_text(buf.getvalue())
    calls = []
    real = np.loadtxt
    monkeypatch.setattr(tables.np, "loadtxt", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(tables, "_first_bad_line", lambda *a, **k: pytest.fail("slow path taken"))
    rec = load_recording(p)
    assert calls == [1]
    np.testing.assert_array_equal(rec.x, data[:, 2])

"""Hostile inputs, generated: configs, recordings, journals and serial frames.

Each property draws inputs a hostile or careless user could give (hypothesis) and holds
the invariant of docs/robustness.md: the input ends in a valid result or in one clean
error (a :class:`~servo.errors.ServoError`, or the one line and exit 2 of the command
line), never another exception; the memory it takes stays under the stated bound
(traced by ``tracemalloc``, which counts numpy's arrays); nothing half-written is left.

The fast tier draws a few dozen examples of each (about 20 s in all); the ``slow``
variants draw many more.  What each draw was, and how it ended, is counted in
:data:`TRIED`; ``pytest -s`` prints the counts (the numbers of docs/robustness.md).
"""
import contextlib
import dataclasses
import io
import json
import os
import tempfile
import tracemalloc
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servo.cli import main
from servo.config import SECTIONS, documented, from_dict
from servo.errors import ServoError
from servo.io.tables import MAX_SAMPLES

#: Examples per property: the fast tier, and the slow variant.
FAST, SLOW = 25, 400
#: Memory a config's inputs may take to build (the largest budget: the HDD benchmark's
#: disturbances, MAX_BENCHMARK_TICKS ticks of ~6 arrays), and a recording to load (two
#: columns at MAX_SAMPLES, read and converted); bytes.
CONFIG_MEMORY = 1 << 30
RECORDING_MEMORY = 2 * 8 * MAX_SAMPLES + (32 << 20)

TRIED: Counter = Counter()


@pytest.fixture(scope="module", autouse=True)
def _report_counts():
    yield
    if TRIED:
        print("\nhostile inputs tried (kind, outcome: count):")
        for (kind, outcome), n in sorted(TRIED.items()):
            print(f"  {kind:10s} {outcome:32s} {n}")


def _examples(fn, strategy):
    """The fast variant (FAST examples) and a ``slow`` one (SLOW) of property ``fn``."""

    @pytest.mark.parametrize("n", [pytest.param(FAST, id="fast"), pytest.param(SLOW, id="slow", marks=pytest.mark.slow)])
    def test(n):
        run = settings(max_examples=n, deadline=None, database=None,
                       suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])(given(strategy)(fn))  # fmt: skip
        run()

    test.__doc__ = fn.__doc__
    return test


@contextlib.contextmanager
def _traced(bound: int, what):
    tracemalloc.start()
    try:
        yield
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        assert peak <= bound, f"{what}: {peak / 1e6:.0f} MB traced, more than {bound / 1e6:.0f} MB"


# -- configs -------------------------------------------------------------------------

def _kind_fields():
    from servo.controllers import KINDS

    return [(f"controller.{kind}", f) for kind, k in KINDS.items() for f in documented(k.Section)]


#: Every field of the sections and of each controller kind's own section (the fresh round
#: found exit 70 in the track and nss designs: tiny inertias, crossovers, gains).
FIELDS = [(name, f) for name, cls in SECTIONS.items() for f in documented(cls)] + _kind_fields()


def _plausible(f, near_only=False):
    """Values near a field's default (scaled by powers of ten, negated), its choices, and
    garbage of every TOML type."""
    d = f.default if f.default is not dataclasses.MISSING else f.default_factory()
    garbage = st.one_of(st.booleans(), st.integers(-(10**20), 10**20), st.just(10**5000), st.floats(), st.sampled_from([5e-324, 1e-300, -1e-300]), st.text(max_size=6),
                        st.lists(st.floats(-1e6, 1e6), max_size=4), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))  # fmt: skip
    near = []
    if isinstance(d, bool):
        near = [st.booleans()]
    elif isinstance(d, (int, float)):
        base = d if d else 1.0
        near = [st.builds(lambda k, s: type(d)(base * 10.0**k * s) if isinstance(d, float) else int(base * 10**k) * s,
                          st.one_of(st.integers(-2, 2), st.integers(-12, 12 if isinstance(d, float) else 6)),
                          st.sampled_from([1, 1, 1, -1]))]  # fmt: skip
    elif isinstance(d, str):
        c = f.metadata["choices"]  # a free text (a path) has none: its default, nothing, a path not there
        near = [st.sampled_from(tuple(c() if callable(c) else c) if c is not None else (d, "", "/no/such/dir"))]
    elif isinstance(d, list):
        near = [st.lists(st.floats(-1e5, 1e5), max_size=8), st.lists(st.floats(0.1, 1e5), min_size=len(d), max_size=len(d))]
    if near_only and near:
        return st.one_of(*near)
    return st.one_of(*near, *near, *near, garbage) if near else garbage  # mostly near: most documents pass the types


@st.composite
def configs(draw):
    """A TOML document: 0-5 fields of the real sections set to plausible or garbage
    values; now and then an unknown key or section, or a section that is not a table."""
    data: dict = {}
    near = draw(st.booleans())  # half the documents: values near the defaults only, so that many pass
    for name, f in draw(st.lists(st.sampled_from(FIELDS), max_size=3 if near else 5)):
        if name.startswith("controller."):  # a kind's field: that kind runs
            kind = name.split(".", 1)[1]
            data.setdefault("controller", {})["kind"] = kind
            data["controller"].setdefault(kind, {})[f.name] = draw(_plausible(f, near))
            continue
        data.setdefault(name, {})[f.name] = draw(_plausible(f, near))
    extra = draw(st.sampled_from(["", "", "", "", "key", "section", "not a table"]))
    if extra == "key":
        data.setdefault("drive", {})[draw(st.text(min_size=1, max_size=5))] = 1.0
    elif extra == "section":
        data[draw(st.text(min_size=1, max_size=5))] = {}
    elif extra == "not a table":
        data["run"] = draw(st.one_of(st.integers(), st.text(max_size=3)))
    return data


def check_config(data):
    """A config is a Config or one ConfigError; an accepted one's run inputs are built
    (or refused) within CONFIG_MEMORY, and are finite."""
    from servo.run.job import prepare

    try:
        cfg = from_dict(data)
    except ServoError:
        TRIED["config", "refused by the config"] += 1
        return
    try:
        with _traced(CONFIG_MEMORY, f"building the inputs of {data}"):
            inputs = prepare(cfg)
    except ServoError:
        TRIED["config", "refused at run time (no folder)"] += 1
        return
    ticks = np.arange(0, min(cfg.n_ticks, 4096), dtype=np.int64)
    for signal in (inputs.reference, inputs.excitation, inputs.disturbance):
        assert np.all(np.isfinite(signal(ticks)))
    TRIED["config", "accepted, inputs built"] += 1


test_configs_end_in_a_config_or_one_error = _examples(check_config, configs())


# -- recordings ----------------------------------------------------------------------

NAMES = st.sampled_from(["t", "u", "x", "v", "r", "t [s]", "x (m)", "q", "", "t", "#c", "é", "a/b"])
VALUES = st.one_of(st.floats(-1e3, 1e3), st.floats(), st.integers(-5, 5), st.just(1e300))


@st.composite
def text_recordings(draw):
    """Delimited text: a header of 1-6 names, 0-60 rows of numbers (a regular time
    column now and then, so that some are valid), a random delimiter; then mutations:
    a junk line, a truncation, random bytes, a BOM, a long line."""
    names = draw(st.lists(NAMES, min_size=1, max_size=6))
    if draw(st.booleans()):
        names = ["t", "u", "x"] + names[3:]
    delim = draw(st.sampled_from([",", ";", "\t", " ", "|"]))
    n = draw(st.integers(0, 60))
    rows = []
    for i in range(n):
        row = [draw(VALUES) for _ in names]
        if names[0] == "t" and draw(st.integers(0, 9)):
            row[0] = i * 1e-3
        rows.append(delim.join(repr(float(v)) if isinstance(v, float) else str(v) for v in row))
    text = delim.join(names) + "\n" + "\n".join(rows) + ("\n" if rows else "")
    data = text.encode("utf-8")
    for mutation in draw(st.lists(st.sampled_from(["junk", "cut", "bytes", "bom", "long", "comma"]), max_size=2)):
        if mutation == "junk":
            at = draw(st.integers(0, len(data)))
            data = data[:at] + b"\n" + draw(st.binary(max_size=20)) + b"\n" + data[at:]
        elif mutation == "cut":
            data = data[: draw(st.integers(0, len(data)))]
        elif mutation == "bytes":
            data = draw(st.binary(max_size=200))
        elif mutation == "bom":
            data = b"\xef\xbb\xbf" + data
        elif mutation == "long":
            data = data + b"1," * 40_000
        elif mutation == "comma":
            data = data.replace(b".", b",")
    return ".csv", data


@st.composite
def npz_recordings(draw):
    """NPZ: 0-5 arrays under drawn names, of drawn shapes and dtypes (a valid t, u, x set
    now and then); sometimes with bytes of the archive overwritten."""
    arrays = {}
    n = draw(st.integers(0, 80))
    if draw(st.booleans()):
        arrays = {"t": np.arange(n) * 1e-3, "u": np.sin(np.arange(n)), "x": np.cos(np.arange(n))}
    for _ in range(draw(st.integers(0, 3))):
        name = draw(st.sampled_from(["t", "u", "x", "v", "r", "q", "meta"]))
        shape = draw(st.sampled_from([(), (n,), (n, 1), (1, n), (2, n), (0,)]))
        dtype = draw(st.sampled_from(["f8", "f4", "i4", "u1", "?", "c16", "U3"]))
        with np.errstate(all="ignore"):  # a drawn float cast to an integer type may overflow: that is the point
            arrays[name] = np.zeros(shape, dtype) if dtype == "U3" else np.full(shape, draw(VALUES), "f8").astype(dtype)
    buf = io.BytesIO()
    (np.savez_compressed if draw(st.booleans()) else np.savez)(buf, **arrays)
    data = bytearray(buf.getvalue())
    for _ in range(draw(st.integers(0, 3))):
        if data:
            data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    return ".npz", bytes(data)


@st.composite
def mat_recordings(draw):
    """MATLAB v5: t, u, x and extra variables (a struct now and then), compressed or not,
    with bytes overwritten now and then."""
    from scipy.io import savemat

    n = draw(st.integers(0, 60))
    variables = {"t": np.arange(n) * 1e-3, "u": np.full(n, draw(VALUES)), "x": np.arange(n) * 1e-6}
    for name in draw(st.lists(st.sampled_from(["t", "u", "x", "v", "scope", "s"]), max_size=3)):
        variables[name] = {"v": np.zeros(n)} if name == "s" else np.full((draw(st.integers(0, 3)), n), draw(VALUES))
    buf = io.BytesIO()
    savemat(buf, variables, do_compression=draw(st.booleans()))
    data = bytearray(buf.getvalue())
    for _ in range(draw(st.integers(0, 3))):
        data[draw(st.integers(128, len(data) - 1))] = draw(st.integers(0, 255))
    return ".mat", bytes(data)


@st.composite
def valid_ish_recordings(draw):
    """t, u, x (and v) as a lab would export them, valid but for a drawn defect or two:
    a NaN, a repeated time, a gap, too few samples, a huge value, a column of text."""
    n = draw(st.integers(10, 80))
    t = np.arange(n) * draw(st.sampled_from([1e-3, 2e-5, 1.0]))
    cols = {"t": t, "u": np.sin(t * 7), "x": np.cos(t * 3) * 1e-3}
    if draw(st.booleans()):
        cols["v"] = np.sin(t)
    for defect in draw(st.lists(st.sampled_from(["nan", "repeat", "gap", "huge", "none"]), max_size=2)):
        name, i = draw(st.sampled_from(sorted(cols))), draw(st.integers(0, n - 1))
        if defect == "nan":
            cols[name][i] = np.nan
        elif defect == "repeat" and i:
            cols["t"][i] = cols["t"][i - 1]
        elif defect == "gap":
            cols["t"][i:] += 0.5
        elif defect == "huge":
            cols[name][i] = 1e200
    if draw(st.booleans()):
        buf = io.BytesIO()
        np.savez(buf, **cols)
        return ".npz", buf.getvalue()
    delim = draw(st.sampled_from([",", ";", "\t", " "]))
    lines = [delim.join(cols)] + [delim.join(repr(float(cols[c][i])) for c in cols) for i in range(n)]
    return ".csv", ("\n".join(lines) + "\n").encode()


RECORDINGS = st.one_of(valid_ish_recordings(), text_recordings(), npz_recordings(), mat_recordings())
MAPPINGS = st.one_of(st.just({}), st.just({}), st.dictionaries(st.sampled_from(["t", "u", "x", "v", "r"]),
                                                 st.sampled_from(["t", "u", "x", "q", "s.v", "scope"]), max_size=2))  # fmt: skip


def check_recording(case):
    """A recording loads valid (finite, time increasing and regular, at least 20 samples,
    columns of one length) or is one RecordingError; within RECORDING_MEMORY; nothing
    written beside it."""
    from servo.io.recording import MIN_SAMPLES, load_recording

    (suffix, data), columns = case
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"rec{suffix}"
        path.write_bytes(data)
        try:
            with _traced(RECORDING_MEMORY, f"loading a {suffix} recording"):
                rec = load_recording(path, columns)
        except ServoError:
            TRIED[f"{suffix[1:]} file", "refused in one line"] += 1
        else:
            assert rec.n >= MIN_SAMPLES and all(a.shape == (rec.n,) for a in (rec.u, rec.x))
            assert np.all(np.isfinite(rec.t)) and np.all(np.diff(rec.t) > 0)
            TRIED[f"{suffix[1:]} file", "loaded valid"] += 1
        assert os.listdir(d) == [path.name]


test_recordings_load_valid_or_are_one_error = _examples(check_recording, st.tuples(RECORDINGS, MAPPINGS))


# -- journals ------------------------------------------------------------------------

JSON = st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=6),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
                    max_leaves=12)  # fmt: skip
COLUMN = st.one_of(st.sampled_from(["t", "x", "u", "tick", "e"]), st.text(max_size=4), st.integers())


@st.composite
def journals(draw):
    """A journal: a header that is a plausible table with drawn columns, units and meta
    (or any JSON, or bytes), then 0-400 bytes of rows (a partial last row now and then)."""
    kind = draw(st.sampled_from(["run log", "run log", "table", "table", "json", "bytes"]))
    if kind == "run log":  # valid but for what the body holds
        header = {"columns": draw(st.lists(st.sampled_from(["t", "x", "u", "tick", "e", "u_c"]), min_size=1, max_size=6,
                                           unique=True)),
                  "units": {"t": "s", "x": "m"}, "meta": draw(st.one_of(st.just({}), st.dictionaries(st.text(max_size=4), JSON, max_size=3)))}  # fmt: skip
        head = (json.dumps(header) + "\n").encode()
    elif kind == "table":
        header = {"columns": draw(st.lists(COLUMN, max_size=5)), "units": draw(st.one_of(
            st.dictionaries(COLUMN.filter(lambda c: isinstance(c, str)), st.text(max_size=4), max_size=3), JSON)),
            "meta": draw(st.one_of(st.just({}), JSON))}  # fmt: skip
        for key in draw(st.lists(st.sampled_from(["columns", "units", "meta"]), max_size=1)):
            header.pop(key)
        head = (json.dumps(header) + "\n").encode()
    elif kind == "json":
        head = (json.dumps(draw(JSON)) + "\n").encode()
    else:
        head = draw(st.binary(max_size=60))
    return head + draw(st.binary(max_size=400)), draw(st.sampled_from(["npz", "csv", "both"]))


def check_journal(case):
    """`servo recover` finalises a journal (the NPZ and CSV hold every complete row of
    every column) or says in one line what is wrong (exit 2) and writes nothing."""
    data, fmt = case
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "log.journal"
        path.write_bytes(data)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = main(["recover", str(path), "--log-format", fmt])
        left = sorted(os.listdir(d))
        if rc == 2:
            assert err.getvalue().startswith("servo: error: ") and err.getvalue().count("\n") == 1, err.getvalue()
            assert left == ["log.journal"]
            TRIED["journal", "refused in one line"] += 1
            return
        assert rc == 0, err.getvalue()
        header = json.loads(data.split(b"\n", 1)[0])
        width = len(header["columns"])
        rows = (len(data) - len(data.split(b"\n", 1)[0]) - 1) // (8 * width)
        assert left == sorted({"npz": ["log.npz"], "csv": ["log.csv"], "both": ["log.npz", "log.csv"]}[fmt])
        if fmt != "csv":
            with np.load(Path(d) / "log.npz") as z:
                assert sorted(z.files) == sorted([*header["columns"], "meta"])
                assert all(z[c].shape == (rows,) for c in header["columns"])
        if fmt != "npz":
            assert len((Path(d) / "log.csv").read_text().splitlines()) == rows + 1
        TRIED["journal", "finalised"] += 1


test_journals_are_finalised_or_one_error = _examples(check_journal, journals())


# -- serial frames -------------------------------------------------------------------


@st.composite
def streams(draw):
    """A byte stream as a board or a line could send it: valid frames of drawn bodies,
    random bytes, flipped bits, long runs without a delimiter, in drawn chunks."""
    from hil.framing import MAX_ENCODED, encode_frame

    parts = []
    from hil import protocol

    messages = st.one_of(
        st.builds(protocol.hello, st.integers(0, 65535), st.integers(0, 2**32 - 1)),
        st.builds(protocol.start, st.integers(0, 65535)), st.builds(protocol.stop, st.integers(0, 65535)),
        st.builds(protocol.fault, st.integers(0, 65535), st.integers(0, 255), st.integers(0, 2**32 - 1), st.text(max_size=30)),
        st.builds(protocol.commands, st.integers(0, 65535), st.integers(0, 2**32 - 1),
                  st.lists(st.floats(width=64), min_size=1, max_size=protocol.MAX_BATCH)),
    )  # fmt: skip
    for kind in draw(st.lists(st.sampled_from(["message", "message", "frame", "bytes", "flip", "long"]), max_size=8)):
        if kind == "message":
            parts.append(encode_frame(draw(messages)))
        elif kind == "frame":
            parts.append(encode_frame(draw(st.binary(max_size=80))))
        elif kind == "bytes":
            parts.append(draw(st.binary(max_size=100)))
        elif kind == "flip":
            f = bytearray(encode_frame(draw(st.binary(min_size=1, max_size=40))))
            f[draw(st.integers(0, len(f) - 1))] ^= 1 << draw(st.integers(0, 7))
            parts.append(bytes(f))
        else:
            parts.append(b"\x01" * (MAX_ENCODED + draw(st.integers(1, 300))))
    data = b"".join(parts)
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=6)))
    return [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)])]


def check_frames(chunks):
    """The frame decoder never raises and stays bounded; every body it passes on parses
    to a message or is one protocol error (Malformed)."""
    from hil.framing import MAX_ENCODED, FrameDecoder
    from hil.protocol import Malformed, parse

    dec = FrameDecoder()
    for chunk in chunks:
        for body in dec.feed(chunk):
            assert dec.buffered <= MAX_ENCODED
            try:
                parse(body)
                TRIED["frame", "parsed"] += 1
            except Malformed:
                TRIED["frame", "refused (Malformed)"] += 1
    TRIED["frame stream", f"{'some rejected' if dec.errors else 'all clean'}"] += 1


test_frames_decode_or_are_counted = _examples(check_frames, streams())


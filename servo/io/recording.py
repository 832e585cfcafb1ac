"""Recordings: load and validate ``t, u, x[, v][, r]`` from the files labs have.

A recording is what a servo engineer brings from the lab (or a run log of this tool):
time ``t`` (s), input ``u`` (A of VCM current, or any force unit after scaling), position
``x`` (m), velocity ``v`` (m/s) when it was measured, and the reference ``r`` (or an
excitation injected in the loop) when the loop was closed: the instrument of a
closed-loop frequency response (``servo frf --closed-loop``).

Formats (read by :func:`servo.io.tables.read_table`, which its docstring details):

* CSV and other delimited text (``.csv .tsv .txt .dat``): a header row naming the
  columns (``t,u,x`` at least; extra columns are ignored, so a ``servo run`` log is a
  recording); ``,`` ``;`` tab ``|`` or spaces; a byte-order mark, ``#`` comments, a
  decimal comma (with another delimiter) and units in brackets (``x [m]``) are
  understood.  Parsed by ``numpy.loadtxt``.
* NPZ: one array per column (a ``servo run`` log NPZ is one).
* MATLAB .mat: v4-v7 via ``scipy.io.loadmat``, v7.3 (HDF5) via ``h5py``; struct fields
  as ``struct.field``.  HDF5 (``.h5``, ``.hdf5``): datasets by path, ``group/name``.

Variables are mapped to roles with ``columns={"u": "vir", "x": "qm"}`` and scaled with
``scale={"u": "gtau"}`` (a number, or the name of a scalar variable in the file), in
every format.

Every problem is a :class:`~servo.errors.RecordingError` with one line that says what is
wrong and where: unreadable file, missing column, unequal lengths, NaN/inf (first
index), time not strictly increasing (first index), a sample period outside
:data:`STEP_RANGE_S`, irregular sampling (gaps), too few samples, a role mapped or
scaled twice.  Whether the data *excite* what a tool wants to identify is the tool's check.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from servo.fields import MAGNITUDE_MAX
from servo.errors import RecordingError
from servo.io.tables import read_table

REQUIRED = ("t", "u", "x")
OPTIONAL = ("v", "r")
MIN_SAMPLES = 20
#: The sample periods a servo recording may have, s: 1 ns (1 GHz) to 1 s (1 Hz).  Outside
#: them the time column is in another unit or scaled wrong (``--scale t=1e-300`` gave a
#: sample rate of 1e304 Hz and overflowing derivatives).
STEP_RANGE_S = (1e-9, 1.0)
#: sampling is "uniform" when every step is within this fraction of the median step
UNIFORM_TOLERANCE = 0.01


@dataclass
class Recording:
    """A validated recording; arrays are float64, shape (n,): ``t`` s, ``u`` A (or the
    force unit), ``x`` m, ``v`` m/s, ``r`` the reference or excitation (``None`` when
    not recorded)."""

    t: np.ndarray
    u: np.ndarray
    x: np.ndarray
    v: np.ndarray | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)
    r: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.t.shape[0]

    @property
    def dt(self) -> float:
        """Sample period (s): the median time step."""
        return float(np.median(np.diff(self.t)))

    @property
    def sample_rate_hz(self) -> float:
        return 1.0 / self.dt

    def slice(self, start: int, stop: int) -> "Recording":
        """Samples ``start:stop`` as a new recording (e.g. a training or test block)."""
        v = None if self.v is None else self.v[start:stop]
        r = None if self.r is None else self.r[start:stop]
        return Recording(self.t[start:stop], self.u[start:stop], self.x[start:stop], v, self.source, dict(self.meta), r)


def parse_mapping(text: str | None, what: str) -> dict[str, str]:
    """``"u=vir,x=qm"`` -> ``{"u": "vir", "x": "qm"}`` (for ``--columns``/``--scale``)."""
    out: dict[str, str] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise RecordingError(f"{what}: expected NAME=VALUE pairs separated by commas, got {item!r}")
        if key.strip() in out:  # "u=1,u=2" took the last without a word
            raise RecordingError(f"{what}: {key.strip()} is given twice ({key.strip()}={out[key.strip()]} and "
                                 f"{key.strip()}={value.strip()})")  # fmt: skip
        out[key.strip()] = value.strip()
    return out


def _scale_factor(value: str, table: dict, path: Path) -> float:
    try:
        return float(value)
    except ValueError:
        pass
    if value not in table:
        raise RecordingError(f"recording: {path}: scale {value!r} is neither a number nor a variable in the file")
    arr = np.asarray(table[value], dtype=float).ravel()
    if arr.size != 1:
        raise RecordingError(f"recording: {path}: scale variable {value!r} is not a scalar")
    return float(arr[0])


def load_recording(path: str | Path, columns: dict[str, str] | None = None, scale: dict[str, str] | None = None,
                   min_samples: int = MIN_SAMPLES) -> Recording:  # fmt: skip
    """Load and validate a recording.  ``columns`` maps ``t/u/x/v`` to names in the file
    (default: the same names); ``scale`` multiplies a column by a number or a scalar
    variable of the file (``{"u": "gtau"}``)."""
    path = Path(path)
    columns = dict(columns or {})
    for key in columns:
        if key not in REQUIRED + OPTIONAL:
            raise RecordingError(f"recording: unknown column role {key!r} (roles: t, u, x, v, r)")
    wanted = {columns.get(role, role) for role in REQUIRED + OPTIONAL} | set((scale or {}).values())
    table = read_table(path, wanted)  # only these are read: an unused column costs nothing
    arrays: dict[str, np.ndarray] = {}
    for role in REQUIRED + OPTIONAL:
        name = columns.get(role, role)
        if name not in table:
            if role in OPTIONAL and role not in columns:
                continue
            have = ", ".join(sorted(table.names)) or "none"
            raise RecordingError(
                f"recording: {path.name} has no column {name!r} for {role} (it has: {have}); map one with --columns {role}=NAME"
            )
        a = np.asarray(table[name])
        if a.dtype.kind not in "fiu" or a.size == 0:
            raise RecordingError(f"recording: {path.name}: column {name!r} is not numeric")
        if a.ndim > 1 and sorted(a.shape)[:-1] != [1] * (a.ndim - 1):
            raise RecordingError(f"recording: {path.name}: column {name!r} has shape {a.shape}, expected a vector")
        arrays[role] = a.astype(float).ravel()
    source = {role: columns.get(role, role) for role in arrays}
    for role in arrays:
        twins = [r for r in arrays if source[r] == source[role]]
        if len(twins) > 1:
            raise RecordingError(f"recording: {path.name}: {' and '.join(twins)} would both be column {source[role]!r}; "
                                 "map each role to its own column (--columns)")  # fmt: skip
    for role, value in (scale or {}).items():
        if role not in arrays:
            raise RecordingError(f"recording: cannot scale {role!r}: no such column")
        arrays[role] = arrays[role] * _scale_factor(value, table, path)

    n = arrays["t"].shape[0]
    for role, a in arrays.items():
        if a.shape[0] != n:
            raise RecordingError(f"recording: {path.name}: column {role} has {a.shape[0]} samples, t has {n}")
    if n < min_samples:
        raise RecordingError(f"recording: {path.name}: {n} samples, at least {min_samples} needed")
    for role, a in arrays.items():
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise RecordingError(f"recording: {path.name}: {role} is NaN or infinite at sample {bad[0]} ({bad.size} samples)")
        big = np.flatnonzero(np.abs(a) > MAGNITUDE_MAX)
        if big.size:
            raise RecordingError(f"recording: {path.name}: {role} = {a[big[0]]:.3g} at sample {big[0]} is beyond any "
                                 f"physical value (|{role}| <= {MAGNITUDE_MAX:g} in SI units): a wrong column or scale?")  # fmt: skip
        peak = float(np.max(np.abs(a)))
        if 0 < peak < 1 / MAGNITUDE_MAX:  # u of 1e-300 A: squares underflow, fits print numpy warnings and fail
            raise RecordingError(f"recording: {path.name}: {role} never exceeds {peak:.3g} in magnitude, below any physical "
                                 f"value (max |{role}| >= {1 / MAGNITUDE_MAX:g} in SI units): a wrong column or scale?")  # fmt: skip
    dt = np.diff(arrays["t"])
    back = np.flatnonzero(dt <= 0)
    if back.size:
        i = back[0]
        raise RecordingError(f"recording: {path.name}: time is not increasing at sample {i + 1} (t = {arrays['t'][i]:.9g} then {arrays['t'][i + 1]:.9g})")
    step = float(np.median(dt))
    if not STEP_RANGE_S[0] <= step <= STEP_RANGE_S[1]:
        raise RecordingError(f"recording: {path.name}: a sample every {step:.3g} s ({1 / step:.3g} Hz), outside the "
                             f"{STEP_RANGE_S[0]:g} to {STEP_RANGE_S[1]:g} s a servo is sampled at: is t in seconds "
                             "(--scale t=FACTOR)?")  # fmt: skip
    off = np.flatnonzero(np.abs(dt - step) > UNIFORM_TOLERANCE * step)
    if off.size:
        i = off[0]
        raise RecordingError(
            f"recording: {path.name}: irregular sampling at sample {i + 1}: step {dt[i]:.6g} s, the median is {step:.6g} s "
            f"({off.size} irregular steps; gaps must be filled or the recording split)"
        )
    meta = {"columns": {r: columns.get(r, r) for r in arrays}, "scale": dict(scale or {}), "format": table.format}
    units = {r: table.units[columns.get(r, r)] for r in arrays if columns.get(r, r) in table.units}
    if units:
        meta["units"] = units
    return Recording(arrays["t"], arrays["u"], arrays["x"], arrays.get("v"), str(path), meta, arrays.get("r"))


def save_recording_csv(path: str | Path, rec: Recording) -> None:
    """Write ``rec`` as a CSV recording (header ``t,u,x[,v][,r]``, ``%.17g``), atomically."""
    from servo.io.runlog import write_csv

    cols = ["t", "u", "x"] + [c for c in OPTIONAL if getattr(rec, c) is not None]
    data = np.column_stack([getattr(rec, c) for c in cols])
    write_csv(Path(path), cols, data)


__all__ = ["Recording", "load_recording", "parse_mapping", "save_recording_csv"]

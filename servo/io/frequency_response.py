"""Frequency responses and their files: NPZ (exact, the loader's input) and CSV (tables).

A :class:`FrequencyResponse` is a complex response ``H`` (output unit per input unit,
e.g. m/A) at frequencies ``f_hz`` (Hz), with, where known, its coherence and the
standard deviation of its random error relative to ``|H|``.  ``servo frf`` and
``servo bode`` write them in one version-independent format, read back with
:func:`load_frequency_responses` and convertible to python-control with
:meth:`FrequencyResponse.to_control`::

    from servo.io.frequency_response import load_frequency_responses
    frf = load_frequency_responses("out/frf.npz")        # {label: FrequencyResponse}
    G = frf["u -> x"].to_control()                       # control.FrequencyResponseData
    FrequencyResponse.from_control(G, unit="m/A")        # and back

:func:`save_mat` (MATLAB, scipy.io) and :func:`save_h5` (HDF5) write the same and the
same loader reads them.

NPZ layout (``numpy.load(path)`` works without this module and without pickles):

* ``format``: the string ``servo-frequency-response/1``;
* ``labels``: strings, shape ``(m,)``, one per response;
* ``f_hz_<i>``, ``H_<i>`` (complex128), ``coherence_<i>``, ``rel_std_<i>``: shape
  ``(n_i,)`` for the i-th label (NaN where unknown);
* ``meta``: a JSON string, ``{label: {...}}`` (units, method, settings).

CSV layout: one row per point, header
``label,f_hz,re,im,mag_db,phase_deg,coherence,rel_std,unit``; the label is quoted when
it holds a comma.  :func:`load_frequency_responses` reads both (the CSV without the meta).
"""
from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from servo.errors import ServoError, first_line
from servo.io.atomic import atomic_write, strict_json

FORMAT = "servo-frequency-response/1"
CSV_HEADER = ("label", "f_hz", "re", "im", "mag_db", "phase_deg", "coherence", "rel_std", "unit")


class FrequencyResponseError(ServoError):
    """A frequency-response file that cannot be read (one line)."""


@dataclass
class FrequencyResponse:
    """A measured frequency response.  Arrays have shape ``(n,)``.

    ``f_hz``: frequencies (Hz, increasing); ``H``: complex response (``unit``, output per
    input); ``coherence``: squared coherence in [0, 1] (of the input with the output,
    or for an instrumental estimate the smaller of instrument-input and
    instrument-output), NaN where unknown; ``rel_std``: standard deviation of the random
    error of ``H`` relative to ``|H|`` (of ``|H|`` in relative terms and of the phase in
    radians), NaN where unknown; ``meta``: method, settings, units (JSON-able)."""

    f_hz: np.ndarray
    H: np.ndarray
    coherence: np.ndarray | None = None
    rel_std: np.ndarray | None = None
    unit: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.f_hz = np.asarray(self.f_hz, dtype=float).ravel()
        self.H = np.asarray(self.H, dtype=complex).ravel()
        n = self.f_hz.size
        self.coherence = np.full(n, np.nan) if self.coherence is None else np.asarray(self.coherence, float).ravel()
        self.rel_std = np.full(n, np.nan) if self.rel_std is None else np.asarray(self.rel_std, float).ravel()
        if not (self.H.size == self.coherence.size == self.rel_std.size == n):
            raise FrequencyResponseError(f"frequency response: f_hz has {n} points, H {self.H.size}, coherence "
                                         f"{self.coherence.size}, rel_std {self.rel_std.size}")  # fmt: skip

    def __repr__(self) -> str:
        n = self.f_hz.size
        if n == 0:
            return f"<FrequencyResponse, no points, {self.unit or 'no unit'}>"
        coh = self.coherence >= 0.9
        good = f", coherence >= 0.9 at {int(coh.sum())}" if np.isfinite(self.coherence).any() else ""
        return (f"<FrequencyResponse {self.meta.get('label', '')!s}: {n} points, {self.f_hz[0]:.4g}-{self.f_hz[-1]:.4g} Hz, "
                f"|H| {np.nanmin(np.abs(self.H)):.3g}-{np.nanmax(np.abs(self.H)):.3g} {self.unit}{good}>").replace(" :", ":")

    def _repr_html_(self) -> str:
        """A short page (:mod:`servo.io.page`): the ``repr`` line and the band's figures."""
        from servo.io.page import Page, Section, Table

        n = self.f_hz.size
        rows = [["points", n], ["unit", self.unit or "-"]] + ([
            ["f (Hz)", f"{self.f_hz[0]:.4g}-{self.f_hz[-1]:.4g}"],
            ["|H| min", float(np.nanmin(np.abs(self.H)))], ["|H| max", float(np.nanmax(np.abs(self.H)))],
            ["coherence >= 0.9", int((self.coherence >= 0.9).sum())]] if n else [])  # fmt: skip
        label = str(self.meta.get("label", "")) or "frequency response"
        return Page(label, [repr(self).strip("<>")], "info", [Section("Response", [Table(rows)])]).fragment()

    @property
    def mag_db(self) -> np.ndarray:
        """``20*log10(|H|)`` (dB re 1 ``unit``)."""
        with np.errstate(divide="ignore"):
            return 20 * np.log10(np.abs(self.H))

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase (deg), unwrapped and shifted so the first point lies in (-360, 0]."""
        if self.H.size == 0:
            return np.zeros(0)
        ph = np.unwrap(np.angle(self.H))
        ph -= 2 * np.pi * math.ceil(ph[0] / (2 * np.pi))
        return np.degrees(ph)

    def to_control(self):
        """This response as :class:`control.FrequencyResponseData` (omega in rad/s)."""
        import control

        return control.FrequencyResponseData(self.H, 2 * np.pi * self.f_hz)

    @classmethod
    def from_control(cls, frd, unit: str = "", meta: dict | None = None) -> "FrequencyResponse":
        """A SISO :class:`control.FrequencyResponseData` (omega in rad/s) as a response
        (no coherence, no error estimate)."""
        w = np.asarray(frd.omega, float)
        H = np.asarray(getattr(frd, "frdata", None) if hasattr(frd, "frdata") else frd.fresp, complex).reshape(-1, w.size)
        if H.shape[0] != 1:
            raise FrequencyResponseError(f"frequency response: a single-input single-output system, got {H.shape[0]} channels")
        return cls(w / (2 * np.pi), H[0], unit=unit, meta=dict(meta or {}))

    def band(self, f_min: float = 0.0, f_max: float = np.inf) -> "FrequencyResponse":
        """The points with ``f_min <= f_hz <= f_max`` (Hz); per-point lists in ``meta``
        (same length as ``f_hz``) are cut alike."""
        m = (self.f_hz >= f_min) & (self.f_hz <= f_max)
        n = self.f_hz.size
        meta = {k: np.asarray(v)[m].tolist() if isinstance(v, list) and len(v) == n else v for k, v in self.meta.items()}
        return FrequencyResponse(self.f_hz[m], self.H[m], self.coherence[m], self.rel_std[m], self.unit, meta)


def _as_dict(responses) -> dict[str, FrequencyResponse]:
    if isinstance(responses, FrequencyResponse):
        return {responses.meta.get("label", "response"): responses}
    return dict(responses)


def save_npz(path: str | Path, responses: dict[str, FrequencyResponse] | FrequencyResponse) -> Path:
    """Write ``{label: FrequencyResponse}`` (or one response) as NPZ, atomically."""
    resp = _as_dict(responses)
    arrays: dict[str, np.ndarray] = {"format": np.array(FORMAT), "labels": np.array(list(resp), dtype=str)}
    meta = {}
    for i, (label, r) in enumerate(resp.items()):
        arrays.update({f"f_hz_{i}": r.f_hz, f"H_{i}": r.H, f"coherence_{i}": r.coherence, f"rel_std_{i}": r.rel_std})
        meta[label] = {"unit": r.unit, **r.meta}
    arrays["meta"] = np.array(strict_json(meta))
    path = Path(path)
    atomic_write(path, lambda tmp: _savez(tmp, arrays))
    return path


def _savez(tmp, arrays):
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


def _fmt(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.10g}"


def save_csv(path: str | Path, responses: dict[str, FrequencyResponse] | FrequencyResponse) -> Path:
    """Write ``{label: FrequencyResponse}`` as one CSV table (see the module docstring), atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_HEADER)
    for label, r in _as_dict(responses).items():
        for f, h, mdb, ph, c, s in zip(r.f_hz, r.H, r.mag_db, r.phase_deg, r.coherence, r.rel_std):
            w.writerow([label, f"{f:.10g}", f"{h.real:.12g}", f"{h.imag:.12g}", f"{mdb:.6f}", f"{ph:.4f}", _fmt(c),
                        _fmt(s), r.unit])  # fmt: skip
    path = Path(path)
    atomic_write(path, lambda tmp: Path(tmp).write_text(buf.getvalue()))
    return path


def save_mat(path: str | Path, responses: dict[str, FrequencyResponse] | FrequencyResponse) -> Path:
    """Write ``{label: FrequencyResponse}`` as MATLAB ``.mat`` (scipy.io), atomically:
    ``format``, ``labels`` (a cell array) and one struct ``r<i>`` per label with
    ``f_hz``, ``H`` (complex), ``coherence``, ``rel_std``, ``unit``, ``meta`` (JSON):
    ``frd(r0.H, 2*pi*r0.f_hz)`` in MATLAB."""
    from scipy.io import savemat

    resp = _as_dict(responses)
    doc = {"format": FORMAT, "labels": np.array(list(resp), dtype=object)}
    for i, r in enumerate(resp.values()):
        doc[f"r{i}"] = {"f_hz": r.f_hz, "H": r.H, "coherence": r.coherence, "rel_std": r.rel_std, "unit": r.unit,
                        "meta": strict_json(r.meta)}  # fmt: skip
    path = Path(path)
    atomic_write(path, lambda tmp: savemat(tmp, doc))
    return path


def save_h5(path: str | Path, responses: dict[str, FrequencyResponse] | FrequencyResponse) -> Path:
    """Write ``{label: FrequencyResponse}`` as HDF5 (h5py), atomically: attribute
    ``format``; one group ``<i>`` per label with attributes ``label``, ``unit``, ``meta``
    (JSON) and datasets ``f_hz``, ``H`` (complex), ``coherence``, ``rel_std``."""
    import h5py

    def write(tmp):
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            for i, (label, r) in enumerate(_as_dict(responses).items()):
                g = f.create_group(str(i))
                g.attrs["label"], g.attrs["unit"], g.attrs["meta"] = label, r.unit, strict_json(r.meta)
                for name in ("f_hz", "H", "coherence", "rel_std"):
                    g.create_dataset(name, data=getattr(r, name))

    path = Path(path)
    atomic_write(path, write)
    return path


def load_frequency_responses(path: str | Path) -> dict[str, FrequencyResponse]:
    """Read a file written by :func:`save_npz`, :func:`save_csv`, :func:`save_mat` or
    :func:`save_h5`: ``{label: FrequencyResponse}`` in the written order.  A file that
    is not one is one :class:`FrequencyResponseError` line."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".npz":
            return _load_npz(path)
        if path.suffix.lower() == ".csv":
            return _load_csv(path)
        if path.suffix.lower() == ".mat":
            return _load_mat(path)
        if path.suffix.lower() in (".h5", ".hdf5"):
            return _load_h5(path)
    except FrequencyResponseError:
        raise
    except FileNotFoundError:
        raise FrequencyResponseError(f"frequency response: no such file: {path}") from None
    except Exception as exc:
        raise FrequencyResponseError(f"frequency response: cannot read {path}: {first_line(exc)}") from None
    raise FrequencyResponseError(f"frequency response: {path}: unknown format {path.suffix!r} (use .npz, .csv, .mat or .h5)")


def _load_npz(path: Path) -> dict[str, FrequencyResponse]:
    with np.load(path, allow_pickle=False) as z:
        if "format" not in z.files or str(z["format"]) != FORMAT:
            raise FrequencyResponseError(f"frequency response: {path} is not a {FORMAT} file")
        meta = json.loads(str(z["meta"]))
        out = {}
        for i, label in enumerate(str(s) for s in z["labels"]):
            m = dict(meta.get(label, {}))
            unit = m.pop("unit", "")
            out[label] = FrequencyResponse(z[f"f_hz_{i}"], z[f"H_{i}"], z[f"coherence_{i}"], z[f"rel_std_{i}"], unit, m)
        return out


def _load_mat(path: Path) -> dict[str, FrequencyResponse]:
    from scipy.io import loadmat

    m = loadmat(path, squeeze_me=True, chars_as_strings=True)
    if str(m.get("format", "")) != FORMAT:
        raise FrequencyResponseError(f"frequency response: {path} is not a {FORMAT} file")
    out = {}
    for i, label in enumerate(np.atleast_1d(m["labels"])):
        r = m[f"r{i}"]

        def field_(name):  # a struct's field comes back as a 0-d object array holding the value
            v = r[name]
            return v.item() if isinstance(v, np.ndarray) and v.dtype == object and v.shape == () else v

        arrays = [np.atleast_1d(field_(n)) for n in ("f_hz", "H", "coherence", "rel_std")]
        unit, meta = field_("unit"), field_("meta")
        out[str(label)] = FrequencyResponse(*arrays, unit=str(unit) if np.size(unit) else "",
                                            meta=json.loads(str(meta)) if np.size(meta) else {})  # fmt: skip
    return out


def _load_h5(path: Path) -> dict[str, FrequencyResponse]:
    import h5py

    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != FORMAT:
            raise FrequencyResponseError(f"frequency response: {path} is not a {FORMAT} file")
        out = {}
        for i in range(len(f)):
            g = f[str(i)]
            out[str(g.attrs["label"])] = FrequencyResponse(g["f_hz"][()], g["H"][()], g["coherence"][()], g["rel_std"][()],
                                                           str(g.attrs["unit"]), json.loads(g.attrs["meta"]))  # fmt: skip
        return out


def _load_csv(path: Path) -> dict[str, FrequencyResponse]:
    with open(path, newline="", encoding="utf-8-sig") as fh:
        rows = list(csv.reader(fh))
    if not rows or tuple(h.strip() for h in rows[0]) != CSV_HEADER:
        raise FrequencyResponseError(f"frequency response: {path}: the header is not {','.join(CSV_HEADER)}")
    groups: dict[str, list] = {}
    for lineno, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(CSV_HEADER):
            raise FrequencyResponseError(f"frequency response: {path} line {lineno}: {len(row)} fields, expected {len(CSV_HEADER)}")
        groups.setdefault(row[0], []).append(row)
    out = {}
    for label, g in groups.items():
        num = np.array([[float(v) if v else np.nan for v in (r[1], r[2], r[3], r[6], r[7])] for r in g])
        out[label] = FrequencyResponse(num[:, 0], num[:, 1] + 1j * num[:, 2], num[:, 3], num[:, 4], g[0][8])
    return out


__all__ = ["FORMAT", "FrequencyResponse", "FrequencyResponseError", "load_frequency_responses", "save_csv", "save_h5",
           "save_mat", "save_npz"]

"""What a controller kind is, and the registry that ``[controller] kind = "..."`` reads.

A kind is one class that owns everything about one controller (see ``docs/controllers.md``
for a worked example):

* ``name``: the value of ``[controller] kind``; ``summary``: one line for the docs;
* ``Section``: a dataclass of :func:`servo.config.P` fields, its config section
  ``[controller.<name>]`` with units and ranges (validated, printed by ``servo config``,
  tabled in ``docs/config.md``);
* ``STATE`` / ``PARAMS``: numpy record dtypes (float64 fields) of its state and
  parameters;
* ``start`` / ``tick`` / ``log``: its compiled kernels on those records, with the
  signatures of :mod:`kernels.compose` (explicit signatures, ``cache=True``);
* ``log_columns`` / ``log_units``: the columns ``log`` writes after the common ones;
* :meth:`params`: its parameter record from its section; :meth:`response`: its linear
  frequency response from the position error to ``u_n`` (what ``servo loop`` sets the
  measured loop against); :meth:`check`: consistency checks across the config.

It sits on the stage of :mod:`kernels.stage` (signals, the paper's compensator, the
current limit): ``u = u_n + u_c``.  Registering it (:func:`register`, one line in
``servo/controllers/__init__.py``) is all the runtime needs: the tick path, the compiled
fast path, the serial link and the real-time pacer run it unchanged.
"""
from __future__ import annotations

import hashlib
import inspect
from typing import ClassVar

import numpy as np

from kernels.compose import Composed, compose
from servo.errors import first_line


class ControllerKind:
    """Base of a controller kind; subclass it, fill the class attributes, :func:`register`.

    ``cfg`` below is the run's :class:`servo.config.Config` (not imported here: the config
    sits above the kinds and gathers their sections)."""

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    Section: ClassVar[type]
    STATE: ClassVar[np.dtype]
    PARAMS: ClassVar[np.dtype]
    start: ClassVar[staticmethod]
    tick: ClassVar[staticmethod]
    log: ClassVar[staticmethod]
    log_columns: ClassVar[tuple[str, ...]] = ()
    log_units: ClassVar[dict[str, str]] = {}

    @classmethod
    def params(cls, section, cfg) -> np.ndarray:
        """The one-element :attr:`PARAMS` record for ``section`` (an instance of
        :attr:`Section`) in ``cfg``."""
        raise NotImplementedError

    @classmethod
    def response(cls, section, cfg, f_hz: np.ndarray) -> np.ndarray:
        """The controller's frequency response ``C(j*2*pi*f)`` from the position error (m)
        to ``u_n`` (A), shape of ``f_hz``, as the discrete controller runs at the tick
        rate (``cfg.dt``)."""
        raise NotImplementedError

    @classmethod
    def to_control(cls, section, cfg):
        """The controller as a discrete python-control system at ``cfg.dt`` (s) from the
        position error (m) to ``u_n`` (A), whose frequency response is :meth:`response`
        (:func:`servo.lti.controller`).  Optional: a kind without one cannot be exported
        or analysed with python-control."""
        raise NotImplementedError

    @classmethod
    def check(cls, section, cfg) -> None:
        """Raise :class:`~servo.errors.ConfigError` if ``section`` does not fit ``cfg``."""

    @classmethod
    def kernels(cls) -> Composed:
        """Its kernels composed with the stage, the log row and the fast loop (compiled or
        loaded from the cache on the first call in a process)."""
        tag = _TAGS.get(cls) or _TAGS.setdefault(cls, source_tag(cls))  # read the sources once per class
        return compose(cls.name, tag, cls.STATE, cls.PARAMS, cls.start, cls.tick, cls.log)


_TAGS: dict[type, str] = {}


def source_tag(kind: type) -> str:
    """Eight hex digits that change whenever the source of ``kind`` or of its kernels
    changes: the module defining the class, the files defining ``start``/``tick``/``log``,
    and, followed through their globals, the files of every kernel they call (a plugin's
    kernels are cached by Numba beside their own files, not in the project's hashed cache
    folder, so the composed kernels must know when any of them changed)."""
    h = hashlib.sha256()
    seen: set = set()
    todo = [kind.start, kind.tick, kind.log]
    files = {inspect.getsourcefile(kind) if inspect.getmodule(kind) else None}
    while todo:
        k = todo.pop()
        fn = getattr(k, "py_func", None)
        if fn is None or id(fn) in seen:
            continue
        seen.add(id(fn))
        try:
            files.add(inspect.getsourcefile(fn))
        except TypeError:
            pass
        code = fn.__code__  # also the bytecode and constants, for kernels with no source file
        h.update(code.co_code + repr(code.co_consts).encode())
        todo += [v for name, v in fn.__globals__.items() if name in code.co_names and hasattr(v, "py_func")]
    for f in sorted(f for f in files if f):
        try:
            h.update(f.encode() + open(f, "rb").read())
        except OSError:
            pass
    return h.hexdigest()[:8]


KINDS: dict[str, type[ControllerKind]] = {}


def register(kind: type[ControllerKind]) -> type[ControllerKind]:
    """Make ``kind`` selectable as ``[controller] kind = "<kind.name>"``.  Checks that it
    is complete: records of float64 fields, its three kernels, its log units."""
    for attr in ("name", "Section", "STATE", "PARAMS", "start", "tick", "log"):
        if not hasattr(kind, attr):
            raise TypeError(f"controller kind {kind.__name__}: missing {attr}")
    if not kind.name.isidentifier():
        raise TypeError(f"controller kind {kind.__name__}: name {kind.name!r} must be an identifier")
    for dt in (kind.STATE, kind.PARAMS):
        if any(dt.fields[f][0].base != np.float64 for f in dt.names):
            raise TypeError(f"controller kind {kind.name}: record fields must be float64")
    missing = [c for c in kind.log_columns if c not in kind.log_units]
    if missing:
        raise TypeError(f"controller kind {kind.name}: no unit for log columns {missing}")
    if kind.name in RESERVED:
        raise TypeError(f"controller kind {kind.__name__}: name {kind.name!r} is a [controller] key")
    if KINDS.get(kind.name, kind) is not kind:
        raise TypeError(f"controller kind {kind.__name__}: name {kind.name!r} is taken by {KINDS[kind.name].__module__}."
                        f"{KINDS[kind.name].__name__}")  # fmt: skip
    _check_log(kind)
    KINDS[kind.name] = kind
    return kind


#: Names a kind cannot take: the keys and attributes of ``[controller]`` itself.
RESERVED = {"kind", "kinds", "section", "current_limit", "velocity_source", "velocity_cutoff_hz", "direction_deadband"}


def _check_log(kind: type[ControllerKind]) -> None:
    """The kind's ``log`` writes exactly ``len(log_columns)`` values: every one of them,
    none beyond (a row past its end would be another column's memory)."""
    n = len(kind.log_columns)
    buf = np.full(n + 8, np.nan)
    state = np.zeros(1, kind.STATE)
    try:
        kind.log(buf[:n], state[0])
    except Exception as exc:
        raise TypeError(f"controller kind {kind.name}: its log kernel cannot be called as log(out, state): "
                        f"{type(exc).__name__}: {first_line(exc)}") from None  # fmt: skip
    if not np.isnan(buf[n:]).all():
        raise TypeError(f"controller kind {kind.name}: its log writes more than its {n} log_columns")
    if np.isnan(buf[:n]).any():
        raise TypeError(f"controller kind {kind.name}: its log leaves some of its {n} log_columns unwritten")


def kind_names() -> tuple[str, ...]:
    """The registered kinds' names (``[controller] kind`` choices).  The built-in kinds are
    registered by the package (:mod:`servo.controllers`), which Python imports before any
    of its modules."""
    return tuple(KINDS)


def get_kind(name: str) -> type[ControllerKind]:
    return KINDS[name]

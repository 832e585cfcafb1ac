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
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from kernels.compose import Composed, compose

if TYPE_CHECKING:
    from servo.config import Config


class ControllerKind:
    """Base of a controller kind; subclass it, fill the class attributes, :func:`register`."""

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
    def params(cls, section, cfg: "Config") -> np.ndarray:
        """The one-element :attr:`PARAMS` record for ``section`` (an instance of
        :attr:`Section`) in ``cfg``."""
        raise NotImplementedError

    @classmethod
    def response(cls, section, cfg: "Config", f_hz: np.ndarray) -> np.ndarray:
        """The controller's frequency response ``C(j*2*pi*f)`` from the position error (m)
        to ``u_n`` (A), shape of ``f_hz``, as the discrete controller runs at the tick
        rate (``cfg.dt``)."""
        raise NotImplementedError

    @classmethod
    def check(cls, section, cfg: "Config") -> None:
        """Raise :class:`~servo.errors.ConfigError` if ``section`` does not fit ``cfg``."""

    @classmethod
    def kernels(cls) -> Composed:
        """Its kernels composed with the stage, the log row and the fast loop (compiled or
        loaded from the cache on the first call in a process)."""
        return compose(cls.name, source_tag(cls), cls.STATE, cls.PARAMS, cls.start, cls.tick, cls.log)


def source_tag(kind: type) -> str:
    """Eight hex digits that change whenever the module defining ``kind`` changes."""
    try:
        text = inspect.getsource(inspect.getmodule(kind)).encode()
    except (OSError, TypeError):  # defined where there is no source file: hash the bytecode
        text = b"".join(getattr(k, "py_func", k).__code__.co_code for k in (kind.start, kind.tick, kind.log))
    return hashlib.sha256(text).hexdigest()[:8]


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
    KINDS[kind.name] = kind
    return kind


def kind_names() -> tuple[str, ...]:
    """The registered kinds' names (``[controller] kind`` choices)."""
    import servo.controllers  # noqa: F401  (registers the built-in kinds)

    return tuple(KINDS)


def get_kind(name: str) -> type[ControllerKind]:
    import servo.controllers  # noqa: F401

    return KINDS[name]

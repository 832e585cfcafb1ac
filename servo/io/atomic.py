"""Atomic file writes: write a temporary beside the target, then rename it into place."""
from __future__ import annotations

import json
import math
import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np


@contextmanager
def naming(path: str | Path):
    """Give an :class:`OSError` raised in the block without a file name (a write that
    meets a full disk or a file-size limit: ``No space left on device``) the name
    ``path``, so that its one error line says where."""
    try:
        yield
    except OSError as exc:
        if exc.filename is None and exc.errno is not None:
            raise type(exc)(exc.errno, exc.strerror or str(exc), str(path)) from None
        raise


def atomic_write(path: Path, write) -> None:
    """Call ``write(tmp_path)`` then rename ``tmp_path`` onto ``path``; never leaves a
    half-written ``path`` (the temporary is removed if ``write`` fails).  A failed
    write's error names ``path`` (:func:`naming`)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with naming(path):
            write(tmp)
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def strict_json(obj) -> str:
    """``obj`` as strict JSON (RFC 8259), indented: a NaN or an infinity, which Python's
    ``json`` would write as the non-JSON ``NaN``/``Infinity``, becomes ``null`` (no
    value); numpy scalars and arrays become numbers and lists."""

    def clean(o):
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if isinstance(o, np.ndarray):
            return clean(o.tolist())
        if isinstance(o, np.generic):
            o = o.item()
        if isinstance(o, float) and not math.isfinite(o):
            return None
        return o

    return json.dumps(clean(obj), indent=2, allow_nan=False)


def write_json(path: Path, obj) -> None:
    """Write ``obj`` to ``path`` atomically as strict JSON (:func:`strict_json`)."""
    text = strict_json(obj)
    atomic_write(path, lambda tmp: Path(tmp).write_text(text + "\n"))

"""Where Numba keeps the compiled kernels: a directory keyed by the kernels' source.

Numba's on-disk cache (``cache=True``) checks only the timestamp of the file that defines
each function.  A kernel that calls (and inlines) a kernel of another file keeps its
cached machine code when only the callee's file changes: after editing ``dahl.py`` the
cached controller tick would still run the old Dahl model.  Keying the cache directory
on a hash of the kernels' source makes any edit start a fresh cache: a kernel declared
with :func:`kernel` is cached under the hash of every ``*.py`` of ``kernels/`` and of the
folder that declares it (a package above declares kernels that inline these, never the
reverse), so this module needs to know nothing of the packages that use it.

The directory is ``$SERVO_NUMBA_CACHE`` or ``~/.cache/servo-numba`` (``$XDG_CACHE_HOME``
if set), then ``<hash>/``.  ``NUMBA_CACHE_DIR``, if the user set it, is respected as is.
Kernels are declared with :func:`kernel`, which points Numba's cache there only while it
compiles or loads them: importing the kernels leaves Numba's configuration unchanged.
"""
from __future__ import annotations

import hashlib
import os
from contextlib import contextmanager
from pathlib import Path

from numba import njit
from numba.core import config

HERE = Path(__file__).resolve().parent


#: Every kernel declared with :func:`kernel` in this process (for :func:`compiled_here`).
DECLARED: list = []


def source_hash(folders) -> str:
    """First 16 hex digits of the SHA-256 of every ``*.py`` in ``folders`` (name, content)."""
    h = hashlib.sha256()
    for folder in folders:
        for path in sorted(folder.glob("*.py")):
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def cache_dir(folder: Path = HERE) -> Path:
    """The cache directory of the kernels declared in ``folder``."""
    base = os.environ.get("SERVO_NUMBA_CACHE")
    if not base:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = Path(xdg) / "servo-numba" if xdg else Path.home() / ".cache" / "servo-numba"
    return Path(base) / source_hash(dict.fromkeys((HERE, Path(folder).resolve())))


def compiled_here() -> bool:
    """Whether this process compiled any kernel declared with :func:`kernel` (those of
    ``kernels/``, of the controller kinds, the composed loops) rather than loading it
    from the cache (the first run after an install, an edit, or a checkout at a new path:
    Numba's index is keyed by the source file's path and time as well)."""
    return any(sum(k.stats.cache_misses.values()) > 0 for k in DECLARED)


@contextmanager
def keyed_cache(folder: Path = HERE):
    """Numba's cache directory set to :func:`cache_dir` of ``folder`` for the block, and restored after:
    the kernels' cache locations are fixed when they are decorated, and Numba's global
    configuration is left as the user had it."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        yield
        return
    path = cache_dir(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:  # no writable cache folder: Numba's default, beside the sources
        yield
        return
    before = config.CACHE_DIR
    config.CACHE_DIR = str(path)
    try:
        yield
    finally:
        config.CACHE_DIR = before


def kernel(signature, **options):
    """``numba.njit(signature, cache=True, **options)``, compiled (or loaded from the keyed
    cache, :func:`keyed_cache`) at decoration: every kernel of this project is declared
    with it, so it has an explicit signature and is ready before any loop runs.  A cache
    that cannot be written (a full disk, a file-size limit) costs a compilation in the
    next process, never the command."""

    def decorate(fn):
        with keyed_cache(Path(fn.__code__.co_filename).resolve().parent):
            try:
                dispatcher = njit(signature, cache=True, **options)(fn)
            except OSError:  # compiled, but its cache could not be written (a full disk): compile uncached
                dispatcher = njit(signature, **options)(fn)
        DECLARED.append(dispatcher)
        return dispatcher

    return decorate


def entry_point(dispatcher, *scratch):
    """The compiled function behind ``dispatcher`` (a :func:`kernel`), called without
    Numba's per-call argument dispatch (~0.3 us for each record-array argument, most of a
    tick's cost when called from Python).

    ``dispatcher(*scratch)`` is called first, on arguments of exactly the types the caller
    will pass (copies of its arrays): it checks them against the kernel's one explicit
    signature and raises as usual if they do not match, so the entry point is only ever
    handed the types it was compiled for.  Falls back to the dispatcher itself when this
    Numba has no entry point to give."""
    dispatcher(*scratch)
    try:
        (sig,) = dispatcher.signatures
        return dispatcher.overloads[sig].entry_point
    except (AttributeError, KeyError, ValueError):
        return dispatcher

"""Where Numba keeps the compiled kernels: a directory keyed by the kernels' source.

Numba's on-disk cache (``cache=True``) checks only the timestamp of the file that defines
each function.  A kernel that calls (and inlines) a kernel of another file keeps its
cached machine code when only the callee's file changes: after editing ``dahl.py`` the
cached controller tick would still run the old Dahl model.  Each kernel's cache directory
is therefore keyed on a hash of every source file of this package (``kernels/``) and of
the folder that defines the kernel (a controller kind's kernels, elsewhere, call into
``kernels/`` and into their neighbours): any edit there starts a fresh cache.

The directory is ``<base>/<hash>/``.  ``base`` is what the application sets with
:func:`configure`, else ``<sys.prefix>/var/cache/kernels-numba`` (inside the Python
environment, so it goes with it), else, when that is not writable, the user's cache
folder (``$XDG_CACHE_HOME`` or ``~/.cache``, then ``kernels-numba``).  ``NUMBA_CACHE_DIR``,
if the user set it, is respected as is.  Kernels are declared with :func:`kernel`, which
points Numba's cache there only while it compiles or loads them: importing the kernels
leaves Numba's configuration unchanged.

Compiling every kernel takes 10-20 s on an idle machine: :func:`watch` lets an
application see each kernel as it is compiled or loaded (and say so).  Importing this
module does not import Numba.
"""
from __future__ import annotations

import hashlib
import inspect
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

HERE = Path(__file__).resolve().parent

_base: Path | None = None
_hashes: dict[Path, str] = {}
_watchers: list[Callable[[str, bool | None, float], None]] = []
#: Every kernel :func:`kernel` declared in this process (for :func:`compiled_here`).
DECLARED: list = []


def configure(base: str | Path | None) -> None:
    """Set the folder the keyed cache directories go into (None: the default of the
    module docstring).  Call it before the first kernel is imported."""
    global _base
    _base = None if base is None else Path(base)


def default_base() -> Path:
    """``<sys.prefix>/var/cache/kernels-numba`` when it can be written, else the user's
    cache folder."""
    inside = Path(sys.prefix) / "var" / "cache" / "kernels-numba"
    try:
        inside.mkdir(parents=True, exist_ok=True)
        if os.access(inside, os.W_OK):
            return inside
    except OSError:
        pass
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "kernels-numba"


def base_dir() -> Path:
    """The folder the keyed cache directories are in."""
    return _base if _base is not None else default_base()


def source_hash(folders=(HERE,)) -> str:
    """First 16 hex digits of the SHA-256 of every ``*.py`` in ``folders`` (name, content)."""
    h = hashlib.sha256()
    for folder in [folders] if isinstance(folders, (str, Path)) else folders:
        for path in sorted(Path(folder).glob("*.py")):
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _folders(where: Path | None) -> tuple[Path, ...]:
    return (HERE,) if where is None or where == HERE else (HERE, where)


def cache_dir(where: str | Path | None = None) -> Path:
    """The keyed cache directory of the kernels defined in folder ``where`` (default:
    this package's own)."""
    where = None if where is None else Path(where).resolve()
    key = where or HERE
    if key not in _hashes:
        _hashes[key] = source_hash(_folders(where))
    return base_dir() / _hashes[key]


def compiled_here() -> bool:
    """Whether this process compiled any kernel (declared with :func:`kernel`, composed
    ones included) rather than loading it from the cache (the first run after an install,
    an edit, or a checkout at a new path: Numba's index is keyed by the source file's
    path and time as well)."""
    return any(sum(k.stats.cache_misses.values()) > 0 for k in DECLARED)


@contextmanager
def watch(callback: Callable[[str, bool | None, float], None]):
    """Within the block, ``callback(name, compiled, seconds)`` is called around each
    kernel declared: with ``compiled=None`` before it is compiled or loaded, then with
    True (it was compiled) or False (loaded from the cache) and the seconds it took."""
    _watchers.append(callback)
    try:
        yield
    finally:
        _watchers.remove(callback)


@contextmanager
def keyed_cache(where: Path | None = None):
    """Numba's cache directory set to :func:`cache_dir` for the block, and restored after:
    the kernels' cache locations are fixed when they are decorated, and Numba's global
    configuration is left as the user had it."""
    from numba.core import config

    if os.environ.get("NUMBA_CACHE_DIR"):
        yield
        return
    path = cache_dir(where)
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


def kernel(signature, *, helper: bool = False, **options):
    """``numba.njit(signature, cache=True, **options)`` with its cache in the keyed
    directory (:func:`keyed_cache`): every kernel of this project is declared with it, so
    it has an explicit signature and is never specialised for other types.

    A kernel is compiled (or loaded from the cache) at decoration, before any loop runs.
    A ``helper`` (a kernel only other kernels call) is loaded when it is first needed:
    when a kernel that calls it is compiled (a cached caller carries the helper's machine
    code with it and never needs it), or at its first call from Python; it is loaded with
    its one signature exactly as at decoration, so nothing else changes.  Loading a
    kernel costs a few ms of LLVM work whether it is used or not: a command whose
    composed kernels come from the cache loads none of their helpers
    (:func:`load_helpers` loads them all, for ``servo warmup``).

    A cache that cannot be written (a full disk, a file-size limit) costs a compilation
    in the next process, never the command."""
    from numba import njit

    def decorate(fn):
        name = f"{fn.__module__}.{fn.__qualname__}"
        with keyed_cache(Path(inspect.getfile(fn)).resolve().parent):
            out = njit(cache=True, **options)(fn)  # the cache's location is fixed here; nothing compiled yet
            if not helper:
                _load(out, signature, name)
                return out
        _defer(out, signature, name, Path(inspect.getfile(fn)).resolve().parent)
        return out

    return decorate


#: Helpers declared and not loaded yet (:func:`load_helpers`).
_DEFERRED: list = []


def _load(dispatcher, signature, name: str) -> None:
    """Compile ``dispatcher`` for ``signature`` or load it from its cache, then allow no
    other specialisation (what ``njit(signature)`` does), telling the watchers."""
    for w in list(_watchers):
        w(name, None, 0.0)
    t0 = time.perf_counter()
    try:
        dispatcher.compile(signature)
    except OSError:  # compiled, but its cache could not be written (a full disk): compile uncached
        from numba.core.caching import NullCache

        dispatcher._cache = NullCache()
        dispatcher.compile(signature)
    dispatcher.disable_compile()
    DECLARED.append(dispatcher)
    compiled = sum(dispatcher.stats.cache_misses.values()) > 0
    for w in list(_watchers):
        w(name, compiled, time.perf_counter() - t0)


def _defer(dispatcher, signature, name: str, where: Path) -> None:
    """Make ``dispatcher`` load itself (:func:`_load`) the first time Numba types a call
    to it (a caller compiling) or Python calls it."""
    cls = type(dispatcher)
    state = {"loaded": False}

    def ensure():
        from numba.core.compiler_lock import global_compiler_lock  # re-entrant: a caller compiling holds it

        with global_compiler_lock:  # two threads calling a helper first: one loads, the other waits
            if not state["loaded"]:
                with keyed_cache(where):
                    _load(dispatcher, signature, name)
                state["loaded"] = True
                _DEFERRED.remove(dispatcher)

    def get_call_template(args, kws):  # a caller is being typed
        ensure()
        return cls.get_call_template(dispatcher, args, kws)

    def compile_for_args(*args, **kws):  # a call from Python found no overload: load, then dispatch as usual
        ensure()
        return dispatcher

    dispatcher.get_call_template = get_call_template
    dispatcher._compile_for_args = compile_for_args
    dispatcher.load = ensure
    _DEFERRED.append(dispatcher)


def load_helpers() -> None:
    """Load every helper declared so far and not loaded yet (``servo warmup``)."""
    for d in list(_DEFERRED):
        d.load()


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

"""A command's output folder, written whole or not at all.

Every command writes into ``OUT.incomplete/`` beside the folder it was asked for and
renames it to ``OUT`` when everything is written: a reader never finds a folder with
some of a command's files.  If the command fails, the staging folder is removed (the
previous state, nothing, is what is left), except where it holds recorded data
(``keep_partial``: a run's logs): then it stays, named ``OUT.incomplete/``, and the
error line says so.  ``OUT`` may be an empty folder; servo never writes into a folder
that holds anything, and never deletes one it did not create.

One writer per output: the staging folder is made with an exclusive ``mkdir`` (of two
commands given the same ``OUT``, the second is refused with one line) and locked
(``flock`` on the folder, released when the command ends, however it ends), so that a
command that continues a staging folder left by an interrupted one (``resume``: a
fleet's ``--resume``) can tell a dead writer's folder from a live one's.
"""
from __future__ import annotations

import errno
import os
import shutil
from contextlib import contextmanager

try:
    import fcntl
except ImportError:  # not POSIX: the exclusive mkdir alone keeps one writer per output
    fcntl = None
from pathlib import Path

from servo.errors import Interrupted, ServoError

SUFFIX = ".incomplete"


class OutputError(ServoError):
    """The output folder cannot be used as asked."""


def staging_dir(final: str | Path) -> Path:
    """Where the outputs of ``final`` are written until they are complete."""
    final = Path(os.path.abspath(final))  # "." and ".." have no name to suffix
    return final.with_name(final.name + SUFFIX)


def _check_final(final: Path) -> None:
    cwd = Path.cwd()
    if final == cwd or final in cwd.parents:
        raise OutputError(f"{final}: is the current folder (or holds it); give a new folder with --out")
    if final.exists() and not final.is_dir():
        raise OutputError(f"{final}: File exists (a file, not a folder); choose another --out")
    if final.exists() and any(final.iterdir()):
        raise OutputError(f"{final}: exists and is not an empty folder; servo writes only new folders "
                          "(choose another --out, or remove it)")  # fmt: skip


def check_output(final: str | Path) -> None:
    """Refuse (one line) an output folder that exists with content, or whose staging
    folder an interrupted command left behind."""
    final = Path(os.path.abspath(final))
    _check_final(final)
    staging = staging_dir(final)
    if staging.exists():
        raise OutputError(f"{staging}: left by an interrupted command, or another one is writing it (a run's recorded "
                          "data stays there, `servo recover` finalises a journal; a fleet continues with --resume); "
                          "remove it or choose another --out")  # fmt: skip


def lock(folder: Path) -> int | None:
    """Lock ``folder`` for this process (an exclusive ``flock``, held until the returned
    descriptor is closed, or the process ends); one line if another process holds it."""
    if fcntl is None:
        return None
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise OutputError(f"{folder}: another command is writing it; wait for it to end or choose another --out") from None
    return fd


def _start(final: Path, resume: bool) -> tuple[Path, int | None]:
    """The locked staging folder of ``final``: a new one, or (``resume``) the one an
    interrupted command left."""
    staging = staging_dir(final)
    if resume and staging.is_dir():
        _check_final(final)
        return staging, lock(staging)
    check_output(final)
    try:
        staging.mkdir(parents=True)
    except FileExistsError:  # another command made it since the check
        raise OutputError(f"{staging}: another command is writing it; wait for it to end or choose another --out") from None
    fd = lock(staging)
    try:
        _check_final(final)  # another command may have finished into it since the check
    except OutputError:
        shutil.rmtree(staging, ignore_errors=True)
        if fd is not None:
            os.close(fd)
        raise
    return staging, fd


@contextmanager
def staged(final: str | Path, keep_partial: bool | str = False, resume: bool = False, kept: str = "recorded data",
           hint: str = ""):  # fmt: skip
    """Yield the staging folder for the outputs of ``final``; rename it to ``final``
    when the block completes.  On an exception the staging folder is removed, unless it
    holds recorded data: files matching the glob ``keep_partial`` (``True``: any file; a
    run passes ``"log_*"``, so a folder holding only its ``config.toml`` goes).  Then it
    stays and the error (a :class:`~servo.errors.ServoError`, or
    :class:`~servo.errors.Interrupted` for Ctrl-C) names it: ``<kept> kept in
    <staging>/``, then ``hint`` (how to continue).
    ``resume``: continue in the staging folder an interrupted command left, if there
    is one (it is locked first: refused while its writer runs).  One writer per output
    (module doc)."""
    final = Path(os.path.abspath(final))
    staging, fd = _start(final, resume)
    try:
        try:
            yield staging
        except BaseException as exc:
            pattern = "*" if keep_partial is True else keep_partial
            keep = bool(pattern) and any(staging.glob(pattern))
            if not keep:
                shutil.rmtree(staging, ignore_errors=True)
            where = f"{kept} kept in {staging}/{'; ' + hint if hint else ''}" if keep else "nothing written"
            if isinstance(exc, KeyboardInterrupt):
                raise Interrupted(where) from None
            if keep and isinstance(exc, ServoError):
                exc.args = (f"{exc}; {where}",)
            full = isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)
            if isinstance(exc, OSError) and (keep or (full and exc.filename is None)):  # name where it was writing
                raise OutputError(f"{exc.filename or staging}: {os.strerror(exc.errno) if full else exc.strerror or exc}; "
                                  f"{where}") from None  # fmt: skip
            raise
        try:
            if final.exists():
                final.rmdir()  # empty (checked before; a command of ours never writes into it)
            os.rename(staging, final)
        except OSError as exc:  # something else wrote into it meanwhile: the outputs stay where they are
            raise OutputError(f"{final}: {exc.strerror or exc} (written meanwhile by something else); the outputs "
                              f"are in {staging}/") from None  # fmt: skip
    finally:
        if fd is not None:
            os.close(fd)

"""A command's output folder, written whole or not at all.

Every command writes into ``OUT.incomplete/`` beside the folder it was asked for and
renames it to ``OUT`` when everything is written: a reader never finds a folder with
some of a command's files.  If the command fails, the staging folder is removed (the
previous state, nothing, is what is left), except where it holds recorded data
(``keep_partial``: a run's logs): then it stays, named ``OUT.incomplete/``, and the
error line says so.  ``OUT`` may be an empty folder; servo never writes into a folder
that holds anything, and never deletes one it did not create.
"""
from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path

from servo.errors import Interrupted, ServoError

SUFFIX = ".incomplete"


class OutputError(ServoError):
    """The output folder cannot be used as asked."""


def staging_dir(final: str | Path) -> Path:
    """Where the outputs of ``final`` are written until they are complete."""
    final = Path(os.path.abspath(final))  # "." and ".." have no name to suffix
    return final.with_name(final.name + SUFFIX)


def check_output(final: str | Path) -> None:
    """Refuse (one line) an output folder that exists with content, or whose staging
    folder an interrupted command left behind."""
    final = Path(os.path.abspath(final))
    cwd = Path.cwd()
    if final == cwd or final in cwd.parents:
        raise OutputError(f"{final}: is the current folder (or holds it); give a new folder with --out")
    if final.exists() and not final.is_dir():
        raise OutputError(f"{final}: File exists (a file, not a folder); choose another --out")
    if final.exists() and any(final.iterdir()):
        raise OutputError(f"{final}: exists and is not an empty folder; servo writes only new folders "
                          "(choose another --out, or remove it)")  # fmt: skip
    staging = staging_dir(final)
    if staging.exists():
        raise OutputError(f"{staging}: left by an interrupted command (a run's recorded data stays there; "
                          "`servo recover` finalises a journal); remove it or choose another --out")  # fmt: skip


@contextmanager
def staged(final: str | Path, keep_partial: bool | str = False):
    """Yield the staging folder for the outputs of ``final``; rename it to ``final``
    when the block completes.  On an exception the staging folder is removed, unless
    it holds recorded data: files matching the glob ``keep_partial`` (``True``: any
    file; a run passes ``"log_*"``, so a folder holding only its ``config.toml`` goes).
    Then it stays and the error (a :class:`~servo.errors.ServoError`, or
    :class:`~servo.errors.Interrupted` for Ctrl-C) names it."""
    final = Path(os.path.abspath(final))
    check_output(final)
    staging = staging_dir(final)
    staging.mkdir(parents=True)
    try:
        yield staging
    except BaseException as exc:
        pattern = "*" if keep_partial is True else keep_partial
        kept = bool(pattern) and any(staging.glob(pattern))
        if not kept:
            shutil.rmtree(staging, ignore_errors=True)
        where = f"recorded data kept in {staging}/" if kept else "nothing written"
        if isinstance(exc, KeyboardInterrupt):
            raise Interrupted(where) from None
        if kept and isinstance(exc, ServoError):
            exc.args = (f"{exc}; {where}",)
        if kept and isinstance(exc, OSError):
            raise OutputError(f"{exc.filename}: {exc.strerror or exc}; {where}") from None
        raise
    if final.exists():
        final.rmdir()  # empty (checked before)
    os.rename(staging, final)

"""The package's version and the commit it runs from, in a module of its own at the
bottom of the import graph (standard library only), so that any module may read them
without importing the ``servo`` facade.

The version comes from the VCS: in a git checkout, ``git describe``; installed,
the metadata setuptools-scm wrote from the tag and commit it was built from; with
neither, :data:`FALLBACK_VERSION` (pyproject's ``fallback_version``).
``from servo._version import __version__`` gives :func:`package_version`.
"""
from __future__ import annotations

import json
import subprocess
from importlib import metadata
from pathlib import Path

#: the distribution's name
DISTRIBUTION = "servo-vcm"
#: the version when neither installed metadata nor git can say (pyproject's fallback_version)
FALLBACK_VERSION = "0.1.0"
#: the checkout the package runs from, when it is one
SOURCE_ROOT = Path(__file__).resolve().parents[1]


def _git(*args: str) -> str | None:
    try:
        r = subprocess.run(["git", "-C", str(SOURCE_ROOT), *args], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() if r.returncode == 0 else None


def _in_checkout() -> bool:
    top = _git("rev-parse", "--show-toplevel")
    return top is not None and Path(top).resolve() == SOURCE_ROOT


def _installed() -> metadata.Distribution | None:
    try:
        return metadata.distribution(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return None


def package_version() -> str:
    """This code's version: in a git checkout, ``git describe`` as
    ``<tag>.post<n>+g<commit>[.dirty]`` (with no tag, :data:`FALLBACK_VERSION` and the
    number of commits); else the installed metadata's (setuptools-scm, from the tag and
    commit it was built from); else :data:`FALLBACK_VERSION`."""
    if not _in_checkout():
        dist = _installed()
        return dist.version if dist is not None else FALLBACK_VERSION
    described = _git("describe", "--tags", "--long", "--dirty", "--always", "--abbrev=12")
    if not described:
        return FALLBACK_VERSION
    dirty = described.endswith("-dirty")
    parts = described.removesuffix("-dirty").rsplit("-", 2)
    if len(parts) == 3 and parts[2].startswith("g"):
        tag, n, sha = parts[0].lstrip("v"), parts[1], parts[2]
    else:
        tag, n, sha = FALLBACK_VERSION, _git("rev-list", "--count", "HEAD") or "0", f"g{parts[-1]}"
    return f"{tag}.post{n}+{sha}" + (".dirty" if dirty else "")


def source_revision() -> dict:
    """``{"commit": sha or None, "dirty": bool or None, "from": ...}``: the git commit of
    the checkout this package runs from (``from`` = ``"checkout"``; ``dirty``: tracked
    files differ from it), or the one pip installed it from (``"install"``, from the
    distribution's ``direct_url.json``), else ``None`` (``"unknown"``)."""
    if _in_checkout():
        commit = _git("rev-parse", "HEAD")
        status = _git("status", "--porcelain", "--untracked-files=no")
        return {"commit": commit, "dirty": None if status is None else bool(status), "from": "checkout"}
    dist = _installed()
    if dist is not None:
        try:
            url = json.loads(dist.read_text("direct_url.json") or "{}")
        except (json.JSONDecodeError, OSError):
            url = {}
        commit = (url.get("vcs_info") or {}).get("commit_id")
        if commit is None and "+g" in dist.version:  # setuptools-scm's local part: g<short sha>
            commit = dist.version.split("+g", 1)[1].split(".")[0]
        return {"commit": commit, "dirty": (".d" in dist.version.split("+", 1)[-1]) if "+" in dist.version else None,
                "from": "install"}  # fmt: skip
    return {"commit": None, "dirty": None, "from": "unknown"}


def __getattr__(name: str):
    if name == "__version__":
        return package_version()
    raise AttributeError(f"module 'servo._version' has no attribute {name!r}")

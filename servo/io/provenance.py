"""Provenance: what a result was computed with, for the ``summary.json`` of every job.

docs/run.md's "same on every rerun" holds for one code, one config, one input,
one set of library versions and one CPU (Numba compiles for the host);
:func:`provenance` records exactly those, so a summary says what it can be compared
with.  The code is pinned by its version, which comes from the VCS (setuptools-scm at
install, ``git describe`` in a checkout that was not installed; ``FALLBACK_VERSION``
with neither), and by the git commit (:func:`~servo._version.source_revision`: of the checkout the
package runs from, or the one pip installed it from), with a flag for uncommitted
changes.  A job run from Python records it as well as one run from the command line
(:func:`or_default`); a table writes it in its schema (:func:`schema_metadata`).
"""
from __future__ import annotations

import hashlib
import json
import platform
import sys
import time
from importlib import metadata
from pathlib import Path

from servo._version import FALLBACK_VERSION, package_version, source_revision

#: distributions whose versions change numbers or the files' format: every dependency
#: (the fleet's Dask scheduling and Parquet tables, the serial link's framing included)
LIBRARIES = ("numpy", "numba", "llvmlite", "scipy", "control", "matplotlib", "h5py", "dask", "distributed",
             "pyarrow", "pyserial", "cobs", "threadpoolctl")


def library_versions(names=LIBRARIES) -> dict[str, str | None]:
    """``{distribution: version}`` from the installed metadata (nothing is imported);
    ``None`` for one that is not installed."""
    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def cpu_model(cpuinfo: str | Path = "/proc/cpuinfo") -> str:
    """The CPU's model name (``model name`` of ``/proc/cpuinfo`` on Linux; else
    ``platform.processor()`` or the machine type)."""
    try:
        for line in Path(cpuinfo).read_text(errors="replace").splitlines():
            key, sep, value = line.partition(":")
            if sep and key.strip() in ("model name", "Model", "Hardware", "cpu model") and value.strip():
                return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def sha256_file(path: str | Path, block: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(block):
            h.update(chunk)
    return h.hexdigest()


def config_hash(cfg) -> str:
    """Hex SHA-256 of the config's canonical TOML (every field, no comments): equal for
    equal configs however they were given (file, ``--set``, defaults)."""
    from servo.config import to_toml

    return hashlib.sha256(to_toml(cfg, comments=False).encode()).hexdigest()


def provenance(config=None, inputs=(), argv: list[str] | None = None) -> dict:
    """The provenance dict: package version and git commit (:func:`source_revision`),
    command line (``argv``, default ``sys.argv``: the interpreter's, from Python), config
    hash (when the job used a :class:`~servo.config.Config`), SHA-256 of each input file,
    Python, the library versions, CPU model, OS, and the UTC time it was made."""
    argv = list(sys.argv if argv is None else argv)
    out = {
        "servo_version": package_version(),
        "source": source_revision(),
        "command": argv,
        "config_sha256": None if config is None else config_hash(config),
        "inputs": {str(p): sha256_file(p) for p in inputs if p is not None and Path(p).is_file()},
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "libraries": library_versions(),
        "cpu": cpu_model(),
        "platform": platform.platform(),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    return out


def or_default(given: dict | None, config=None, inputs=()) -> dict:
    """``given`` (what the command line made), else :func:`provenance` of a job started
    from Python (its ``command`` is the interpreter's ``sys.argv``)."""
    return given if given is not None else provenance(config, inputs)


def schema_metadata(prov: dict, units: dict[str, str] | None = None) -> dict[bytes, bytes]:
    """Key-value metadata for a table's schema (``pyarrow.schema(..., metadata=...)``,
    Parquet keeps it): ``servo.provenance`` (JSON of ``prov``) and ``servo.units`` (JSON
    ``{column: unit}``)."""
    out = {b"servo.provenance": json.dumps(prov, sort_keys=True).encode()}
    if units is not None:
        out[b"servo.units"] = json.dumps(units, sort_keys=True).encode()
    return out


__all__ = ["FALLBACK_VERSION", "LIBRARIES", "config_hash", "cpu_model", "library_versions", "or_default",
           "package_version", "provenance", "schema_metadata", "sha256_file", "source_revision"]

"""What the machine has left: available memory and free disk space, checked before a job
allocates or writes anything large, so that an impossible request is one clear line."""
from __future__ import annotations

import shutil
from pathlib import Path

from servo.errors import ServoError


class ResourceError(ServoError):
    """The job needs more memory or disk than the machine has."""


def available_memory() -> float | None:
    """``MemAvailable`` of ``/proc/meminfo`` in bytes; None where it cannot be read."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def free_disk(path: str | Path) -> float | None:
    """Free bytes on the file system that holds ``path`` (or its nearest existing parent)."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return float(shutil.disk_usage(p).free)
    except OSError:
        return None


def check_disk(path: str | Path, need_bytes: float, what: str, advice: str) -> None:
    """Raise :class:`ResourceError` if ``what`` needs more than the free space at ``path``."""
    free = free_disk(path)
    if free is not None and need_bytes > free:
        raise ResourceError(f"{path}: {what}: about {_size(need_bytes)} of disk needed, {_size(free)} free; {advice}")


def check_memory(need_bytes: float, what: str, advice: str) -> None:
    """Raise :class:`ResourceError` if ``what`` needs more memory than is available."""
    avail = available_memory()
    if avail is not None and need_bytes > avail:
        raise ResourceError(f"{what}: about {_size(need_bytes)} of memory needed, {_size(avail)} available; {advice}")


def _size(b: float) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if b >= scale:
            return f"{b / scale:.3g} {unit}"
    return f"{b:.0f} B"


__all__ = ["ResourceError", "available_memory", "check_disk", "check_memory", "free_disk"]

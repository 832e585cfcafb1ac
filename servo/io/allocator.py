"""The C allocator's handling of large arrays, for a command that makes many of them.

glibc serves an allocation above its ``mmap`` threshold (which rises with what is freed,
up to 32 MB) with fresh pages and returns them to the system when it is freed.  A
diagnosis at 1e7 samples allocates and frees thousands of 80 MB arrays, and the kernel
faults and zeroes every page of each one again: 47-54 s of system time out of 113-121 s
(``docs/studies/2026-11-28-diagnose-at-1e7.md``), where at 1e6 samples the same 8 MB
arrays are reused from the heap.  :func:`keep_freed_memory` has glibc serve every
allocation from its heap and keep up to ``keep_bytes`` of freed memory for reuse: at
3e6 samples a diagnosis's system time fell from 4.4 s to 1.1 s with the same peak
memory.

It changes the whole process, so only a command calls it (``servo diagnose``, for a
recording of :data:`LARGE_SAMPLES` or more), never an import or a library function.
"""
from __future__ import annotations

import ctypes
import sys

#: recordings from this many samples up have ``servo diagnose`` call :func:`keep_freed_memory`
#: (8 MB a full-rate column: below it glibc's own threshold already reuses the arrays, and a
#: test process diagnosing small recordings in-process keeps its allocator as it was)
LARGE_SAMPLES = 1_000_000

#: glibc's ``mallopt`` parameters (``malloc.h``)
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4


def keep_freed_memory(keep_bytes: int = 1 << 30) -> bool:
    """Have glibc's ``malloc`` take every allocation from its heap (no ``mmap`` of its own;
    it still maps memory when the heap cannot grow) and keep up to ``keep_bytes`` (bytes)
    of freed memory at the heap's top instead of returning it.  Returns whether it was
    applied: False off Linux or where the C library has no ``mallopt`` (or refuses)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return mallopt(M_MMAP_MAX, 0) == 1 and mallopt(M_TRIM_THRESHOLD, int(min(keep_bytes, 2**31 - 1))) == 1


__all__ = ["LARGE_SAMPLES", "M_MMAP_MAX", "M_TRIM_THRESHOLD", "keep_freed_memory"]

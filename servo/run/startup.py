"""How long this process has been running: the cold start of a command, in seconds.

``servo run`` reports the time from process start to its first tick (interpreter, imports,
loading the cached kernels, configure).  Linux only (``/proc``); elsewhere None.  The
process start is known to the kernel's clock tick (10 ms at ``CLK_TCK = 100``).
"""
from __future__ import annotations

import os
import time


def process_age_s() -> float | None:
    """Seconds since this process started, or None where ``/proc`` is not available."""
    try:
        with open("/proc/self/stat", encoding="ascii") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        start_ticks = int(fields[19])  # field 22 of proc(5): starttime, in clock ticks since boot
        return time.clock_gettime(time.CLOCK_BOOTTIME) - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError, AttributeError):
        return None

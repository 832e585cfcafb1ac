"""A board served by a child process (the firmware's host build, QEMU, ``servo emulate``):
its stdout read line by line, and its end.

The lines are read from the pipe's descriptor into the process's own buffer
(``proc.pending``, bytes): a ``select`` on the pipe beside a file object's ``readline``
would miss lines the file object had already buffered (two lines arriving together, as a
fault line and the next one).
"""
from __future__ import annotations

import os
import select
import subprocess
import time


def read_line(proc: subprocess.Popen, timeout: float) -> str | None:
    """The process's next stdout line (without its newline), or None at EOF or after
    ``timeout`` s.  ``proc.pending`` holds what was read past that line (set it to ``b""``
    when the process starts)."""
    end = time.monotonic() + timeout
    fd = proc.stdout.fileno()
    while b"\n" not in proc.pending:
        ready, _, _ = select.select([fd], [], [], max(0.0, end - time.monotonic()))
        chunk = os.read(fd, 4096) if ready else b""
        if not chunk:
            return None
        proc.pending += chunk
    line, _, proc.pending = proc.pending.partition(b"\n")
    return line.decode()


def end(proc: subprocess.Popen, grace_s: float = 5.0) -> None:
    """End the process if it runs (SIGTERM, then SIGKILL after ``grace_s``), and close its pipes."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(grace_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    for f in (proc.stdout, proc.stderr):
        if f is not None:
            f.close()

"""``python -m bench.startprobe diagnose REC [OPTIONS...]``: a command's fixed cost.

Runs ``servo diagnose REC OPTIONS...`` in this fresh process exactly as ``python -m
servo`` does (:func:`servo.cli.main`) and stops it as soon as the recording is read:
what the command pays before its first sample (the interpreter, its imports, the
cached kernels, parsing the command line, reading the file) and nothing of the
diagnosis itself, which grows with the recording.  Prints one JSON object:
``{"fixed_s": seconds from process start to the recording read, "samples": N,
"modules": {"scipy.signal": true, ...}}``.

Process start is the kernel's (:func:`servo.run.startup.process_age_s`, as ``servo
run``'s cold start), so the interpreter's own start-up counts.
"""
from __future__ import annotations

import json
import sys

WATCHED = ("numba", "scipy.linalg", "scipy.signal", "scipy.stats", "scipy.optimize", "matplotlib", "dask", "pyarrow",
           "h5py", "control")  # fmt: skip


class _Read(BaseException):
    """Raised once the recording is read: stops the command there."""


def main(argv: list[str]) -> int:
    if not argv or argv[0] != "diagnose":
        print("usage: python -m bench.startprobe diagnose REC [OPTIONS...]", file=sys.stderr)
        return 2
    import servo.cli
    import servo.cli.diagnose as command
    from servo.run.startup import process_age_s

    got = {}
    read = command.recording_from_args

    def stop_after_reading(args):
        rec = read(args)
        got.update(fixed_s=process_age_s(), samples=len(rec.t))
        raise _Read

    command.recording_from_args = stop_after_reading
    try:
        status = servo.cli.main(argv + ["--quiet"])
    except _Read:
        status = 0
    if not got:
        print(f"bench.startprobe: the command ended (status {status}) before reading a recording", file=sys.stderr)
        return 1
    got["modules"] = {m: m in sys.modules for m in WATCHED}
    print(json.dumps(got))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

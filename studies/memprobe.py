"""Peak memory of a diagnosis, measured: ``python -m studies.memprobe 100000 1000000``.

For each sample count ``N`` a concealed-hysteresis recording (the benchmark's: a Dahl
pivot of 0.2 mA, long-stroke scenario, ``N/50000`` s at 50 kHz) is built once, saved as
``.npz`` and diagnosed in a fresh Python process.  That process loads the recording,
notes its resident memory, runs :func:`servo.diagnose.job.diagnose` (not the plots or
the files; with the allocator setting the command makes for a recording of
:data:`servo.io.allocator.LARGE_SAMPLES` samples or more) and reports the peak resident memory (``VmHWM``, its high-water mark reset
just before; ``ru_maxrss`` where that is missing) less the memory before
the diagnosis: what the diagnosis itself adds.  It also prints what
:func:`servo.diagnose.job.memory_estimate` predicted, the figure the diagnosis compares
with the available memory before it starts.

Building the recording in another process matters: the simulation's own peak would
otherwise hide a smaller diagnosis peak.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import json, resource, sys, time
import numpy as np
from servo.io.recording import Recording

def status_mb(field):
    try:
        for line in open("/proc/self/status"):
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None

def rss_mb():
    return status_mb("VmRSS") or resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

def peak_mb():
    # VmHWM, the high-water mark of this process's memory: ru_maxrss would carry the
    # parent's resident size over the fork (a pytest session's hundreds of MB)
    return status_mb("VmHWM") or resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

def reset_peak():
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass

from servo.diagnose.job import Options, diagnose
try:
    from servo.diagnose.job import memory_estimate
except ImportError:  # a version without the estimate
    memory_estimate = lambda n, opt: float("nan")
from servo.identify.regressors import RobustSettings
try:
    from servo.io.allocator import LARGE_SAMPLES, keep_freed_memory
except ImportError:  # a version without the setting
    LARGE_SAMPLES, keep_freed_memory = float("inf"), None
z = np.load(sys.argv[1])
rec = Recording(z["t"], z["u"], z["x"], None, source="memprobe")
if rec.n >= LARGE_SAMPLES:  # the allocator setting servo diagnose makes once the recording is loaded
    keep_freed_memory()
opt = Options(settings=RobustSettings(decimate=int(sys.argv[2])))
reset_peak()
before = rss_mb()
peak_before = peak_mb()
t0 = time.perf_counter()
D = diagnose(rec, opt)
seconds = time.perf_counter() - t0
peak = peak_mb()
print(json.dumps({"n": int(rec.n), "before_mb": before, "peak_before_mb": peak_before, "peak_mb": peak,
                  "extra_mb": peak - before, "estimate_mb": memory_estimate(rec.n, opt) / 2**20,
                  "seconds": seconds, "findings": [f.physics for f in D.findings]}))
"""


def recording_file(n: int, folder: Path) -> Path:
    """The benchmark's recording of ``n`` samples, saved once in ``folder``."""
    path = folder / f"hysteresis-{n}.npz"
    if not path.exists():
        import numpy as np

        from servo.diagnose.concealed import Scenario, concealed_recording
        from servo.runtime import closedloop

        cap = closedloop.MAX_MEMORY_ROWS  # an in-memory run's guard (8.4e6 ticks); 1e7 samples fit in memory here
        closedloop.MAX_MEMORY_ROWS = max(cap, n)
        try:
            rec, _ = concealed_recording("hysteresis", 2e-4, seed=1, scenario=Scenario(duration_s=n / 50_000))
        finally:
            closedloop.MAX_MEMORY_ROWS = cap
        np.savez(path, t=rec.t, u=rec.u, x=rec.x)
    return path


def measure(path: Path, decimate: int = 10, python: str = sys.executable, env: dict | None = None) -> dict:
    """Diagnose the recording at ``path`` in a fresh process; its figures (MB, s)."""
    out = subprocess.run([python, "-c", CHILD, str(path), str(decimate)], capture_output=True, text=True, env=env)
    if out.returncode:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies.memprobe", description=__doc__.splitlines()[0])
    p.add_argument("samples", nargs="+", type=int, help="sample counts, e.g. 100000 250000 500000 1000000")
    p.add_argument("--decimate", type=int, default=10, help="the rows' decimation factor (default 10)")
    p.add_argument("--keep", metavar="DIR", help="keep the recordings in DIR (default: a temporary folder)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.keep) if args.keep else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        print(f"{'samples':>10} {'extra MB':>9} {'B/sample':>9} {'estimate MB':>12} {'s':>6}  findings")
        for n in args.samples:
            r = measure(recording_file(n, folder), args.decimate)
            print(f"{r['n']:>10} {r['extra_mb']:>9.0f} {r['extra_mb'] * 2**20 / r['n']:>9.0f} "
                  f"{r['estimate_mb']:>12.0f} {r['seconds']:>6.1f}  {','.join(r['findings'])}", flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

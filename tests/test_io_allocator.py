"""``keep_freed_memory``: a large array freed and allocated again reuses its memory
instead of being faulted in afresh; importing the module changes nothing."""
import json
import subprocess
import sys

CHILD = r"""
import json, resource, sys
import numpy as np
import numpy._core.multiarray as mu
mu._set_madvise_hugepage(False)  # count 4 kB faults: huge pages would fault 2 MB at a time
import servo.io.allocator as al
applied = al.keep_freed_memory() if sys.argv[1] == "on" else None
def faults(n=10_000_000):
    a = np.ones(n); del a                      # 80 MB allocated, touched and freed
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.ones(n)                             # and again
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0
print(json.dumps({"applied": applied, "faults": faults()}))
"""


def _run(mode):
    out = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_freed_memory_is_reused_only_when_asked():
    default, kept = _run("off"), _run("on")
    assert kept["applied"] is True and default["applied"] is None
    assert default["faults"] > 15_000  # 80 MB of 4 kB pages faulted again: glibc's default for a large block
    assert kept["faults"] < 0.1 * default["faults"]  # reused from the heap

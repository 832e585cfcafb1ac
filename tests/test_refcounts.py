"""No reference counting per sample on the fast path (issue 29, item 1).

Numba increments and decrements an array's reference count (atomic operations the C loop
does not have) around a call that is handed the array when it cannot prove the pair
useless.  The plant step and the composed closed loop are recompiled here without the
cache (cached code cannot be inspected) and their LLVM read: the plant step has none, and
the closed loop only those of its array arguments on entry and exit, once per call of
thousands of ticks.
"""
import re

import pytest
from numba import njit

from kernels.plant import plant_step
from servo.config import Config
from servo.runtime.controller import Controller


def _body(dispatcher, name: str) -> str:
    """The LLVM of the function ``name`` (its own body, not the Python wrapper) compiled
    afresh from ``dispatcher``'s source and signature."""
    fresh = njit(dispatcher.signatures[0])(dispatcher.py_func)
    (ir,) = fresh.inspect_llvm().values()
    bodies = [m.group(0) for m in re.finditer(r"^define [^@]*@([\w.$]+)\(.*?^}", ir, re.S | re.M)
              if name in m.group(1) and m.group(1).startswith("_ZN7kernels")]  # fmt: skip
    assert len(bodies) == 1, [b.splitlines()[0][:120] for b in bodies]
    return bodies[0]


def test_the_plant_step_counts_no_references():
    body = _body(plant_step, "plant_step")
    assert "rigid_advance" in body  # the body, with its calls (rigid_substep is inlined in rigid_advance)
    assert "@NRT_incref(" not in body and "@NRT_decref(" not in body


@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_the_closed_loop_counts_references_only_on_entry_and_exit(kind):
    closed_loop = Controller(Config().replace(controller={"kind": kind})).kernels.closed_loop
    body = _body(closed_loop, "closed_loop")
    n_arrays = sum(1 for t in closed_loop.signatures[0] if hasattr(t, "ndim"))
    blocks = re.split(r"^[\w.]+:.*$", body, flags=re.M)  # [define line, the entry block, ...]
    assert len(blocks) > 3
    entry = blocks[0] + blocks[1]
    # one increment per array argument, all on entry, before the loop; as many decrements
    assert body.count("@NRT_incref(") == entry.count("@NRT_incref(") == n_arrays
    assert body.count("@NRT_decref(") == n_arrays

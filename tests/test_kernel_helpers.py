"""Helpers (kernels only other kernels call) load when first needed, with their one
signature: a command whose composed kernels come from the cache does not pay for them."""
import json
import subprocess
import sys

from kernels import _cache

PROBE = """
import json
import kernels.plant as plant
from servo.config import Config
from servo.runtime.controller import Controller
from servo.runtime.simdriver import SimDriver
from servo.scenarios import scenario_inputs
from kernels import _cache
cfg = Config()
drv = SimDriver(cfg, scenario_inputs(cfg))
drv.configure()
ctl = Controller(cfg)
ctl.warm_up()
before = len(plant.rigid_advance.overloads)
loop_before = len(ctl.kernels.closed_loop.overloads)
y = plant.dead_zone(3, 1)                      # ints: converted to the one float64 signature, as before
print(json.dumps({"rigid_advance_before": before, "closed_loop_before": loop_before, "dead_zone": y,
                  "dead_zone_signatures": [str(s) for s in plant.dead_zone.signatures],
                  "deferred": len(_cache._DEFERRED)}))
"""


def test_a_cached_run_loads_no_helper_and_a_python_call_loads_its_one_signature():
    _cache.load_helpers()  # this process: the cache holds every helper (compiled here if it did not)
    from servo.config import Config
    from servo.runtime.controller import Controller

    Controller(Config()).kernels.closed_loop  # the composed kernels cached before the fresh process
    r = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["rigid_advance_before"] == 0  # the plant step and the closed loop came from the cache with its code
    assert got["closed_loop_before"] == 0  # the tick path's controller, warmed, does not load the fast path's loop
    assert got["deferred"] > 20
    assert got["dead_zone"] == 2.0 and got["dead_zone_signatures"] == ["(float64, float64)"]


def test_warmup_loads_every_helper():
    from servo.runtime.warmup import compile_all

    compile_all()
    assert _cache._DEFERRED == []
    from kernels.dahl import dahl_flow

    assert [str(s) for s in dahl_flow.signatures] == ["(float64, float64, float64, float64, float64, float64)"]

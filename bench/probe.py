"""``python -m bench.probe``: what a fresh process pays before and at its first tick.

Imports the kernels and ``servo.run.job`` (timed), runs 2000 ticks of the tick path on
the default drive, then lists every Numba dispatcher of ``kernels`` that compiled instead
of loading from the on-disk cache, or that gained a specialization beyond its explicit
signatures (i.e. compiled inside the loop).  Prints one JSON object.
"""
from __future__ import annotations

import json
import sys
import tempfile
import time


def main() -> int:
    t0 = time.perf_counter()
    import importlib
    import pkgutil

    import kernels

    for m in pkgutil.iter_modules(kernels.__path__):  # compiles or loads every kernel
        importlib.import_module(f"kernels.{m.name}")

    t1 = time.perf_counter()
    import servo.run.job  # noqa: F401

    t2 = time.perf_counter()
    from numba.core.registry import CPUDispatcher

    from kernels.compose import LOG_COLUMNS
    from servo.config import Config
    from servo.io.runlog import RunLog
    from servo.runtime.controller import Controller
    from servo.runtime.loop import run_closed_loop
    from servo.scenarios import scenario_inputs
    from servo.runtime.simdriver import SimDriver

    cfg = Config().replace(run={"duration_s": 0.04})
    inputs = scenario_inputs(cfg)
    with tempfile.TemporaryDirectory() as tmp:
        with SimDriver(cfg, inputs) as drv, RunLog(tmp, "probe", LOG_COLUMNS) as log:
            res = run_closed_loop(cfg, drv, Controller(cfg), inputs, log)
    dispatchers = {}
    for name, mod in list(sys.modules.items()):
        if name == "kernels" or name.startswith("kernels."):
            for attr, obj in vars(mod).items():
                if isinstance(obj, CPUDispatcher):
                    dispatchers[f"{obj.py_func.__module__}.{obj.py_func.__name__}"] = obj
    compiled = sorted(n for n, d in dispatchers.items() if sum(d.stats.cache_misses.values()) > 0)
    extra = sorted(n for n, d in dispatchers.items() if len(d.overloads) > len(d.signatures))
    print(json.dumps({
        "import_kernels_s": t1 - t0,
        "import_runjob_s": t2 - t1,
        "dispatchers": len(dispatchers),
        "compiled_not_cached": compiled,
        "specialised_after_import": extra,
        "first_tick_us": res.timing.first / 1e3,
        "tick_us_median": res.timing.quantile(0.5) / 1e3,
    }))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Servo runtime and modeling tool for precision voice-coil actuators.

Gong, Guo, Lee, Yao, "Modeling and Cancellation of Pivot Nonlinearity in Hard Disk
Drives", IEEE Trans. Magnetics 38(5), 2002, as a fixed-rate servo runtime with a compiled
core (:mod:`kernels`).  The packages' layers, bottom up, are listed (and checked) in
``tests/test_layers.py``; this facade is their top and imports what it offers lazily.
"""


def _kernel_cache() -> None:
    """Where the compiled kernels are cached: ``$SERVO_NUMBA_CACHE`` if set, else the
    default of :mod:`kernels._cache` (inside the Python environment)."""
    import os

    from kernels import _cache

    if os.environ.get("SERVO_NUMBA_CACHE"):
        _cache.configure(os.environ["SERVO_NUMBA_CACHE"])


_kernel_cache()


#: What a notebook needs, imported on first use (``import servo`` imports none of it):
#: name -> (module, attribute; None for the module itself).
API = {
    "load_recording": ("servo.io.recording", "load_recording"),  # CSV, NPZ, MAT, HDF5 -> Recording
    "Recording": ("servo.io.recording", "Recording"),  # arrays you have -> Recording
    "load_run": ("servo.io.runfolder", "load_run"),  # a servo run folder -> RunFolder
    "simulate": ("servo.run.memory", "simulate"),  # servo run in memory -> RunFolder
    "identify": ("servo.identify", None),  # servo.identify(rec, ...): paper eq. 3-5
    "diagnose": ("servo.diagnose", None),  # servo.diagnose(rec, Options(...)) -> Diagnosis
    "compensate": ("servo.compensate", None),  # servo.compensate(report, base) -> a [compensator]
    "frf": ("servo.frf", None),  # servo.frf(rec, closed_loop=...) -> FrequencyResponse
    "loop": ("servo.loop", None),  # servo.loop(cfg) -> control.StateSpace C*P
    "lti": ("servo.lti", None),  # python-control objects of every linear model
    "Config": ("servo.config", "Config"),  # Config().replace(drive={...}, run={...})
    "load_config": ("servo.config", "load_config"),  # a TOML file -> Config
}


def __getattr__(name: str):
    """The names of :data:`API`, imported when first used (``import servo`` stays
    light); ``servo.__version__`` (:func:`servo._version.package_version`)."""
    import importlib

    if name == "__version__":
        from servo._version import package_version

        return package_version()
    if name in API:
        module, attr = API[name]
        mod = importlib.import_module(module)
        return mod if attr is None else getattr(mod, attr)
    raise AttributeError(f"module 'servo' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *API, "__version__"])

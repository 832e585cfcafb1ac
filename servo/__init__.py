"""Servo runtime and modeling tool for precision voice-coil actuators.

Gong, Guo, Lee, Yao, "Modeling and Cancellation of Pivot Nonlinearity in Hard Disk
Drives", IEEE Trans. Magnetics 38(5), 2002, as a fixed-rate servo runtime with a compiled
core (:mod:`kernels`).  The packages' layers, bottom up, are listed (and checked) in
``tests/test_layers.py``; this facade is their top and imports what it offers lazily.
"""
from servo._version import __version__


def _kernel_cache() -> None:
    """Where the compiled kernels are cached: ``$SERVO_NUMBA_CACHE`` if set, else the
    default of :mod:`kernels._cache` (inside the Python environment)."""
    import os

    from kernels import _cache

    if os.environ.get("SERVO_NUMBA_CACHE"):
        _cache.configure(os.environ["SERVO_NUMBA_CACHE"])


_kernel_cache()


def __getattr__(name: str):
    """``servo.load_run``, imported when first used (``import servo`` stays light)."""
    if name == "load_run":
        from servo.io.runfolder import load_run

        return load_run
    raise AttributeError(f"module 'servo' has no attribute {name!r}")

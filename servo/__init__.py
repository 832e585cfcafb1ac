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


#: What a notebook needs, imported on first use (``import servo`` imports none of it).
API = ("load_recording", "Recording", "load_run", "simulate", "identify", "diagnose", "compensate", "frf", "loop",
       "lti", "Config", "load_config")


def __getattr__(name: str):
    """The names of :data:`API`, imported when first used (``import servo`` stays
    light); ``servo.__version__`` (:func:`servo._version.package_version`).

    * ``load_recording(path, columns=..., scale=...)`` -> a ``Recording`` (CSV, NPZ, MAT,
      HDF5); ``Recording(t, u, x)`` from arrays you have;
    * ``load_run(folder)`` -> a ``servo run`` folder; ``simulate(cfg, ...)`` the same run
      in memory;
    * ``identify(rec, ...)``, ``diagnose(rec, ...)``, ``compensate(report, base)``,
      ``frf(rec, ...)``, ``loop(cfg, f_hz)``: the analysis packages, callable (their
      main function);
    * ``lti``: python-control objects of every linear model (``lti.loop(cfg)``);
    * ``Config`` (``Config().replace(drive={...})``), ``load_config(path)``.
    """
    if name == "__version__":
        from servo._version import package_version

        return package_version()
    if name in ("load_recording", "Recording"):
        from servo.io import recording as module
    elif name == "load_run":
        from servo.io import runfolder as module
    elif name == "simulate":
        from servo.run import memory as module
    elif name in ("Config", "load_config"):
        from servo import config as module
    elif name == "identify":
        import servo.identify as module
    elif name == "diagnose":
        import servo.diagnose as module
    elif name == "compensate":
        import servo.compensate as module
    elif name == "frf":
        import servo.frf as module
    elif name == "loop":
        import servo.loop as module
    elif name == "lti":
        import servo.lti as module
    else:
        raise AttributeError(f"module 'servo' has no attribute {name!r}")
    return module if name in ("identify", "diagnose", "compensate", "frf", "loop", "lti") else getattr(module, name)


def __dir__() -> list[str]:
    return sorted([*globals(), *API, "__version__"])

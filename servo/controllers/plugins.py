"""Plugins: modules that define controller kinds, loaded by name or path (``--plugin``).

Loading one imports it and registers every :class:`~servo.controllers.ControllerKind`
subclass it defines (a module does not register itself: importing it changes nothing).
The fleet's workers load the same plugins before they build a drive's config.
"""
from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import sys
from pathlib import Path

from servo.controllers.base import ControllerKind, register
from servo.errors import ConfigError

_LOADED: set[str] = set()


def load_plugins(modules: list[str] | None) -> None:
    """Import each module (a name on the path, or a ``.py`` file) and register every
    :class:`ControllerKind` subclass it defines; a module already loaded is skipped (a
    fleet's worker is asked once per drive)."""
    modules = [m for m in modules or [] if m not in _LOADED]
    if modules and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())  # a plugin in the current folder, as `python -m` would find it
    for name in modules:
        try:
            if name.endswith(".py") or "/" in name:  # a file
                spec = importlib.util.spec_from_file_location(Path(name).stem, name)
                if spec is None or spec.loader is None:
                    raise ImportError(f"no module in {name}")
                mod = importlib.util.module_from_spec(spec)
                sys.modules[spec.name] = mod
                spec.loader.exec_module(mod)
            else:
                mod = importlib.import_module(name)
        except Exception as exc:  # an error in the plugin's code is the plugin's: one line
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            raise ConfigError(f"--plugin {name}: cannot import it ({type(exc).__name__}: {first})") from None
        kinds = [k for k in vars(mod).values() if inspect.isclass(k) and issubclass(k, ControllerKind)
                 and k.__module__ == mod.__name__ and "name" in vars(k)]  # fmt: skip
        if not kinds:
            raise ConfigError(f"--plugin {name}: it defines no controller kind (a ControllerKind subclass with a name)")
        for k in kinds:
            try:
                register(k)
            except TypeError as exc:
                raise ConfigError(f"--plugin {name}: {exc}") from None
        _LOADED.add(name)

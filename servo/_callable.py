"""Subpackages that are also the function they are named after, for a notebook:
``servo.identify(rec)`` is :func:`servo.identify.job.identify`, while ``servo.identify``
stays the package (``import servo.identify.plots`` works as before).  The function's
module is imported on the first call, so importing the package stays light."""
from __future__ import annotations

import importlib
import sys
import types


def make_callable(package: str, target: str) -> None:
    """Make the module ``package`` callable as ``target`` (``"module:function"``)."""
    module_name, name = target.split(":")

    class CallablePackage(types.ModuleType):
        def __call__(self, *args, **kwargs):
            return getattr(importlib.import_module(module_name), name)(*args, **kwargs)

    CallablePackage.__call__.__doc__ = f"Call :func:`{module_name}.{name}` (see its documentation)."
    sys.modules[package].__class__ = CallablePackage

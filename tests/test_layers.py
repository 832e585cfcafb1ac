"""The import graph has layers: every import runs down, none in a circle, lazy ones included.

:data:`LAYERS` lists the packages bottom up (a package is ``kernels``, ``hil``,
``studies``, a second-level package of ``servo`` such as ``servo.runtime``, or a module
directly in ``servo/``); a package may import only packages of lower layers.  The one exception is the
``servo`` facade (``servo/__init__.py``), the top, which imports what it offers lazily.
Imports are read from the source with :mod:`ast` (nothing is imported), so an import inside
a function counts as much as one at the top: it hides a circle from Python, not from a
reader.  A new package goes into :data:`LAYERS` where it belongs.
"""
from __future__ import annotations

import ast
import graphlib
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOP_LEVEL = ("kernels", "servo", "hil", "studies")

#: bottom up; a package imports only packages of the layers below its own
LAYERS = [
    ["kernels", "servo.errors", "servo._version", "servo._callable", "servo.design"],
    ["servo.fields", "servo.hdd"],  # config fields; the HDD benchmark's plant and signals
    ["servo.physics"],  # one module per physical effect: its config fields, records, term
    ["servo.controllers", "servo.scenarios"],  # controller kinds, scenario kinds
    ["servo.config"],
    ["servo.io"],
    ["servo.runtime", "servo.identify", "servo.frf"],
    ["servo.run", "servo.diagnose", "servo.loop", "hil"],
    ["servo.compensate", "servo.fleet"],
    ["servo.experiments", "servo.lti"],  # python-control objects of every model
    ["servo.cli"],
    ["servo.__main__", "servo"],  # the facade: servo/__init__.py
    ["studies"],  # research harnesses, not installed
]
FLOOR = {name: i for i, layer in enumerate(LAYERS) for name in layer}


def modules() -> dict[str, Path]:
    found = {}
    for top in TOP_LEVEL:
        for path in (ROOT / top).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            found[name.removesuffix(".__init__")] = path
    return found


def imports(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules of ours it imports (``from a import b`` counts ``a.b`` when
    that is a module, else ``a``)."""
    out = defaultdict(set)
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([node.module] if node.module else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            else:
                continue
            out[name].update(t for t in targets if t in mods and t != name)
    return out


def package(module: str) -> str:
    parts = module.split(".")
    if parts[0] == "servo" and len(parts) > 1:
        return ".".join(parts[:2])
    return parts[0]


MODS = modules()
ARROWS = imports(MODS)


def test_every_package_has_a_layer():
    assert sorted({package(m) for m in MODS} - set(FLOOR)) == []


def test_imports_run_down():
    upward = sorted(f"{a} -> {b}" for a, bs in ARROWS.items() for b in bs
                    if package(a) != package(b) and FLOOR[package(b)] >= FLOOR[package(a)])  # fmt: skip
    assert upward == []


def test_no_module_imports_in_a_circle():
    try:
        graphlib.TopologicalSorter(ARROWS).prepare()
    except graphlib.CycleError as exc:
        pytest.fail(f"import circle: {' -> '.join(exc.args[1])}")


def test_kernels_import_nothing_of_servo():
    assert sorted(f"{a} -> {b}" for a, bs in ARROWS.items() if a.startswith("kernels") for b in bs
                  if not b.startswith("kernels")) == []  # fmt: skip


def test_the_reader_sees_lazy_imports():
    """The check would be blind without this: the facade's lazy import is an arrow."""
    assert "servo.io.runfolder" in ARROWS["servo"]

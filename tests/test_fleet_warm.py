"""A fleet's worker plugin imports the command's modules as the worker joins
(``servo.fleet.warm``, docs/fleet.md)."""
import sys

from servo.fleet.warm import WarmImports


def test_the_plugin_imports_its_modules_and_leaves_a_failing_one_to_the_task():
    sys.modules.pop("colorsys", None)
    plugin = WarmImports(("colorsys", "servo_no_such_module"))
    plugin.setup(worker=None)  # the worker is not read: only the imports happen
    assert "colorsys" in sys.modules  # imported
    assert "servo_no_such_module" not in sys.modules  # failed quietly: the first task that needs it reports it
    assert plugin.seconds is not None and plugin.seconds >= 0.0
    assert plugin.name == "servo-warm-imports"  # one plugin per worker, whatever the number of fleets it serves

"""Controller kinds: ``[controller] kind = "..."`` selects one (see ``docs/controllers.md``).

Each kind is one module; registering it is one line here.  The runtime's
:class:`servo.runtime.controller.Controller` runs whichever is configured.
"""
from servo.controllers.base import KINDS, ControllerKind, get_kind, kind_names, register
from servo.controllers.nss import NSS
from servo.controllers.pi import PI
from servo.controllers.track import Track

register(PI)
register(Track)
register(NSS)

__all__ = ["KINDS", "ControllerKind", "get_kind", "kind_names", "register"]

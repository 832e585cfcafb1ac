"""Units that follow the recording: the force's (A, N, N*m, ...) and the position's (m or rad).

A linear actuator records its position in m and its force in N (or the current, A); a
rotary one, such as the head arm of a disk drive about its pivot, records an angle in
rad and a torque in N*m (or the current).  The equations the tools fit are the same, so
only the units printed and written change: a parameter's unit is a template in which a
force token (``A`` or ``F``) and ``m`` stand for the recording's units, and
:func:`substitute` writes it for a recording (``B``: ``A*s/m`` -> ``N*m*s/rad``).
"""
from __future__ import annotations

import re

from servo.errors import ConfigError

#: the position units a recording may be in
POSITION_UNITS = ("m", "rad")


def substitute(template: str, force: str = "A", position: str = "m", force_token: str = "A") -> str:
    """``template`` with every whole-word ``force_token`` replaced by ``force`` and every
    whole-word ``m`` by ``position``, in one pass (so the ``m`` of a force ``N*m`` is
    kept): ``substitute("A*s^2/m", "N*m", "rad")`` is ``"N*m*s^2/rad"``."""
    pattern = re.compile(rf"(?<![\w]){re.escape(force_token)}(?![\w])|(?<![\w])m(?![\w])")
    return pattern.sub(lambda m: force if m.group(0) == force_token else position, template)


def position_unit(given: str | None, declared: str | None = None) -> str:
    """The position unit of a recording: ``given`` (``--position-unit``), else the unit
    the file declares for ``x`` (a CSV header ``x [rad]``), else m; one line if it is not
    one of :data:`POSITION_UNITS`."""
    unit = (given or declared or "m").strip()
    if unit not in POSITION_UNITS:
        where = "--position-unit" if given else "the recording's unit of x"
        raise ConfigError(f"{where} {unit!r}: expected one of {', '.join(POSITION_UNITS)}")
    return unit


__all__ = ["POSITION_UNITS", "position_unit", "substitute"]

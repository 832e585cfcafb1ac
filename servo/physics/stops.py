"""The hard stops at ``+-stroke`` (the arm's travel), the reference of the stroke-relative fields.

The effect's config field and plant mapping; the diagnosis does not name it (a recording
that reaches a stop is refused, not modelled).
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import Effect, one_field

EFFECT = Effect(
    "hard_stops", "hard stops at +-stroke",
    drive=dict(stroke=P(15e-3, "m", "hard stops at +-stroke", 0.0, None, lo_open=True)),
    plant=one_field("stroke"),
    not_cancellable="a hard stop is the end of the travel: keep the motion inside it",
    simulated=lambda d, sim: {"stroke": sim.stroke},  # stops the motion never reaches
)  # fmt: skip

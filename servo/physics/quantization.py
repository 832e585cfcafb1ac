"""A quantised position sensor (an encoder's count).

The effect's config fields, plant and compensator mappings, diagnosis term and
documentation entry (:class:`~servo.physics.base.Effect`).
"""
from __future__ import annotations

from servo.fields import P
from servo.physics.base import Concealment, DriveMap, Effect, Search, SignalPath, Term


class Quantization(Term):
    name, thetas, units = "quantization", ("step",), {"step": "m", "offset": "m"}
    doc = "position sensor quantised to a lattice of step `step` (an encoder's count)"
    path = SignalPath(kind="sensor")
    search = Search(never="a sensor effect: tested on its own (servo.diagnose.quantization)")


class QuantizationDrive(DriveMap):
    """The quantization term in the simulated drive's ``[drive]`` section."""

    name = "quantization"
    absent = {"position_quantum": 0.0}  # a found lattice is a finding, not a fitted term

    def to_drive(self, P, fit):
        return {"position_quantum": P[self.name]["step"]}

    def in_drive(self, d):
        return d.position_quantum > 0


def _conceal(size):
    return {"position_quantum": size}


_STUDY = Concealment("quantization", "m", "position quantum", (5e-9, 1e-8, 2e-8, 5e-8, 1e-7), 5e-8, fields=_conceal)


EFFECT = Effect(
    "quantization", "position sensor quantised to a lattice",
    drive=dict(position_quantum=P(1.0e-9, "m", "position quantisation step (0: none)", 0.0)),
    plant=lambda d, dt: {"quantum": d.position_quantum},
    term=Quantization(),
    not_cancellable="the sensor's resolution is not a force: nothing to cancel (a finer encoder, or a velocity "
                    "cutoff that averages over several steps)",
    drive_map=QuantizationDrive(),
    study=_STUDY,
    simulated=lambda d, sim: {"position_quantum": 0.0},
    diagnosed_by="lattice",
)  # fmt: skip

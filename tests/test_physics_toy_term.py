"""A new diagnosis term needs only the required interface: a feature library's.

A toy effect, a quadratic drag ``c*x'*|x'|``, is registered with a term that declares
its name, doc, units, coefficient and columns and nothing else (no capability, no
``[drive]`` field), and a recording whose input carries that drag is diagnosed with
it: the diagnosis names it, fits ``c`` and reports it in its unit, with no pipeline
line that knows the term.
"""
from __future__ import annotations

import numpy as np
import pytest

from servo import physics
from servo.diagnose.job import diagnose
from servo.diagnose.report import build_report
from servo.io.recording import Recording
from servo.physics.base import DriveMap, Effect, Term
from studies.proving.cases import Case, recording

#: what a term's author may write at the least (servo/physics/base.py, ``Term``)
REQUIRED = {"name", "doc", "units", "coefs", "thetas", "full", "grid", "bounds"}


class QuadraticDrag(Term):
    name, doc = "toy_quadratic_drag", "a drag c*x'*|x'| (a toy: columns only)"
    coefs, units = ("c",), {"c": "F*s^2/m^2"}

    def full(self, d, theta, u_eff):
        return d.sig.vf * np.abs(d.sig.vf)


def test_the_toy_term_declares_only_the_required_interface():
    own = {k for k in vars(QuadraticDrag) if not k.startswith("_")}
    assert own <= REQUIRED
    for cap in ("path", "search", "judging"):  # each capability is the default, bound to the toy
        assert type(getattr(QuadraticDrag(), cap)) is type(getattr(Term, cap))


def test_a_term_with_the_required_interface_alone_is_diagnosed():
    rec, _ = recording(Case("null", 0.0, "force", "multisine", 5000.0), 11)  # open loop: the input is the force
    vf = diagnose(rec).sig.vf  # the diagnosis's own filtered velocity, from the position alone
    drag = vf * np.abs(vf)
    c = 0.3 * np.std(rec.u) / np.std(drag)  # the drag: 30 % of the input's RMS
    rec2 = Recording(rec.t, rec.u + c * drag, rec.x, rec.v, "toy drag", r=rec.r)
    toy = Effect(QuadraticDrag.name, QuadraticDrag.doc, term=QuadraticDrag(), drive_map=DriveMap())
    physics.register(toy)
    try:
        D = diagnose(rec2)
        report = build_report(D)
    finally:  # the registry as it was
        physics.EFFECTS.pop(toy.name, None)
        physics.VOCABULARY.pop(toy.name, None)
    names = [f.physics for f in D.findings]
    assert names == [toy.name], (names, D.verdict["text"])
    assert D.findings[0].params["c"] == pytest.approx(c, rel=0.02)
    assert D.verdict["verdict"] == "explained", D.verdict["text"]
    assert report["findings"][0]["physics"] == toy.name and report["findings"][0]["units"]["c"] == "A*s^2/m^2"
    assert toy.name not in physics.VOCABULARY and toy.name not in physics.EFFECTS

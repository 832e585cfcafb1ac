"""The rows cache of a diagnosis (``servo.diagnose.model.Design``): bounded in bytes,
and what it drops is computed again to the bit, so a diagnosis with a tiny cache
reports what one with the whole cache reports."""

import json

import numpy as np
import pytest

from servo.diagnose import job
from servo.diagnose import model as model_mod
from servo.diagnose.concealed import Scenario, concealed_recording
from servo.diagnose.model import Model, Term
from servo.diagnose.report import build_report


@pytest.fixture(scope="module")
def rec():
    rec, _ = concealed_recording("hysteresis", 5e-4, seed=21, scenario=Scenario(duration_s=1.0))
    return rec


@pytest.fixture()
def design(rec):
    opt = job.Options()
    return job.prepare(rec, opt.settings or job.RobustSettings(), opt)


def _report(D) -> str:
    r = build_report(D)
    r.pop("provenance", None)
    r.pop("seconds", None)
    return json.dumps(r, sort_keys=True, default=repr)


@pytest.mark.slow  # two diagnoses, one computing every column again each time it is asked for
def test_a_diagnosis_with_a_tiny_cache_reports_the_same(rec, monkeypatch):
    whole = _report(job.diagnose(rec))
    monkeypatch.setattr(model_mod, "ROWS_BUDGET", 1)  # one entry kept: everything else computed again
    assert _report(job.diagnose(rec)) == whole


def test_the_cache_keeps_its_budget_most_recent_first(design, monkeypatch):
    col = design.sig.m * 8
    monkeypatch.setattr(model_mod, "ROWS_BUDGET", 3 * col)
    made = []

    def make(i):
        made.append(i)
        return np.full(design.sig.m, float(i))

    for i in range(5):
        design.cached_rows(("k", i), lambda i=i: make(i))
    assert design._rows_bytes == sum(v.nbytes for v in design._rows.values()) <= 3 * col
    assert list(design._rows) == [("k", 2), ("k", 3), ("k", 4)]
    design.cached_rows(("k", 2), lambda: make(-1))  # a hit: not made again, now the most recent
    design.cached_rows(("k", 5), lambda: make(5))  # drops ("k", 3), the least recent
    assert made == [0, 1, 2, 3, 4, 5]
    assert list(design._rows) == [("k", 4), ("k", 2), ("k", 5)]
    assert design.cached_rows(("k", 0), lambda: make(0))[0] == 0.0 and made[-1] == 0  # dropped: made again


def test_forget_keeps_the_rows_of_the_given_models(design):
    base = Model([Term.make(p) for p in ("inertia", "viscous_friction", "coulomb_friction", "offset")])
    y, Phi, _ = design.matrix(base)
    hyst = Term.make("hysteresis", {"dahl_length": 2e-6})
    design.term_rows(hyst, base)
    design.target_raw(base, Term.make("time_delay", {"delay_s": 4e-5}))
    n = len(design._rows)
    design.forget(keep=[base])
    assert len(design._rows) == n - 2 and design._rows_bytes == sum(v.nbytes for v in design._rows.values())
    y2, Phi2, _ = design.matrix(base)
    assert len(design._rows) == n - 2  # nothing the base model asks for was dropped
    assert np.array_equal(y, y2) and np.array_equal(Phi, Phi2)
    assert np.array_equal(design.target(base), y)

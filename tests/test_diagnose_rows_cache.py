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


def test_the_cache_keeps_its_budget_dropping_the_entries_never_asked_for_again(design, monkeypatch):
    col = design.sig.m * 8
    monkeypatch.setattr(model_mod, "ROWS_BUDGET", 3 * col)
    made = []

    def get(i):
        def make():
            made.append(i)
            return np.full(design.sig.m, float(i))

        return design.cached_rows(("k", i), make)

    for i in range(5):  # a scan: the newest entry never asked for again goes, the first ones stay
        get(i)
    assert design._rows_bytes == sum(v.nbytes for v in design._rows.values()) <= 3 * col
    assert list(design._rows) == [("k", 0), ("k", 1), ("k", 4)]
    get(0)  # found: not made again, now the most recent and asked for again
    get(5)  # drops ("k", 4), the newest of those never asked for again
    assert list(design._rows) == [("k", 1), ("k", 0), ("k", 5)]
    get(1), get(5)  # every entry asked for again: the least recently used goes next
    get(6)
    assert list(design._rows) == [("k", 1), ("k", 5), ("k", 6)]
    assert made == [0, 1, 2, 3, 4, 5, 6]
    assert get(0)[0] == 0.0 and made[-1] == 0  # dropped: made again, the same


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

"""The term interface stays a feature library's (studies/term_interface.py, the counts
of docs/studies/2026-11-28-term-interface.md): a new hook on ``Term`` itself, or a line
of the diagnosis pipeline that names a term, fails here."""
from __future__ import annotations

import pytest

from studies.term_interface import measure


@pytest.fixture(scope="module")
def m():
    return measure()


def test_the_required_interface_is_a_feature_librarys(m):
    assert m["required"] == ["name", "coefs", "thetas", "units", "doc", "full", "grid", "bounds", "rows", "physical",
                             "from_physical", "unit"]  # fmt: skip
    assert set(m["capabilities"]) == {"path", "search", "judging"}


def test_no_pipeline_line_names_a_term(m):
    # the one hit is a homonym: the sensor lattice's "offset" parameter, not the term
    assert [line.split(":")[0] for line in m["naming_lines"]] == ["servo/diagnose/job.py"]
    assert '"offset": lat.offset' in m["naming_lines"][0]


def test_every_capability_member_a_term_overrides_is_used_by_the_pipeline(m):
    """A member some term overrides that no pipeline line reads would be a dead hook."""
    used = {h for h, sites in m["call_sites"].items() if sites}
    overridden = {h for o in m["overrides"].values() for h in o if "." in h}
    # values a capability's own method reads: Judging.note (the report's) and Search.eligible
    assert overridden - used == {"judging.positive", "search.never"}

"""The physics registry: every effect in one module, the config sections, the records
and the docs derived from the modules, and nothing of an effect left outside them."""
from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import servo.diagnose  # noqa: F401  (registers the terms that live beside the diagnosis)
from kernels.plant import PLANT_PARAMS
from kernels.stage import STAGE_PARAMS
from servo import physics
from servo.config import CompensatorConfig, Config, DriveConfig, from_dict
from servo.fields import documented
from servo.physics.base import (EQ9, Cancelling, Capability, Effect, Judging, Search, SignalPath, Simulation,
                                Term)  # fmt: skip
from servo.runtime.controller import stage_params
from servo.runtime.simplant import plant_params

ROOT = Path(__file__).resolve().parents[1]


def test_every_effect_is_one_module_of_the_registry():
    files = {p.stem for p in (ROOT / "servo" / "physics").glob("*.py")} - {"__init__", "base"}
    assert files == set(physics.MODULES)
    assert set(physics.FILES.values()) == {f"servo/physics/{m}.py" for m in physics.MODULES}


def test_the_config_sections_are_the_effects_fields():
    drive = {f.name for f in documented(DriveConfig)}
    comp = {f.name for f in documented(CompensatorConfig)}
    assert {k for k, _ in physics.drive_fields()} <= drive
    assert {k for k, _ in physics.compensator_fields()} <= comp
    # what the sections hold beyond the effects' fields is the simulation's and the switch's own
    assert drive - {k for k, _ in physics.drive_fields()} == {"substeps", "initial_position"}
    assert comp - {k for k, _ in physics.compensator_fields()} == {
        "enabled", "fast_on_speed", "fast_off_speed", "fast_on_distance", "authority"}  # fmt: skip


def test_the_plant_record_is_filled_by_the_effects():
    assert set(physics.plant_values(Config().drive, 2e-5)) | {"dt", "n_sub"} == set(PLANT_PARAMS.names)


def test_each_effect_sets_the_record_fields_of_its_own_config_fields():
    """Changing one effect's drive field changes the plant record, and only in fields
    that effect's plant mapping sets: no effect reads another's fields."""
    base = Config()
    ref = plant_params(base.drive, base.dt)
    for e in physics.EFFECTS.values():
        mine = set(e.plant(base.drive, base.dt)) if e.plant else set()
        for k, f in e.drive.items():
            v = getattr(base.drive, k)
            if isinstance(v, bool) or isinstance(v, list):
                continue
            lo, hi = f.metadata["lo"], f.metadata["hi"]
            new = v * 0.5 if v else hi / 2 if hi else 1e-3
            changed = plant_params(dataclasses.replace(base.drive, **{k: new}), base.dt)
            diff = {n for n in PLANT_PARAMS.names if changed[n][0] != ref[n][0]}
            assert diff and diff <= mine, (e.name, k, diff, mine)


def test_the_stage_record_engages_its_extras_from_the_effects():
    c = Config()
    assert stage_params(c)["extras"][0] == 0.0
    for key, value in (("b_asymmetry", 0.1), ("coulomb_extra", 1e-4), ("coulomb_static", 1e-4),
                       ("periodic_amplitudes", [1e-5])):  # fmt: skip
        extra = {"periodic_phases": [0.0]} if key == "periodic_amplitudes" else {}
        assert stage_params(c.replace(compensator={key: value, **extra}))["extras"][0] == 1.0, key
    on = stage_params(c.replace(compensator={"kf_linear": 0.1}))
    assert on["kf_on"][0] == 1.0 and on["kf1"][0] == 0.1


def test_registry_refuses_a_second_owner_of_a_field():
    clash = Effect("twin_viscous", "a second B", drive={"B": dataclasses.field(default=0.0)})
    with pytest.raises(ValueError, match="already viscous_friction's"):
        physics.register(clash)
    assert "twin_viscous" not in physics.EFFECTS


def test_every_vocabulary_term_has_an_effect_module_and_a_compensator_answer():
    assert set(physics.VOCABULARY) == set(physics.NAMES)
    for name, term in physics.VOCABULARY.items():
        e = physics.EFFECTS[name]
        assert isinstance(term, Term)
        # a term is either cancelled (its compensator fields, or left out by one) or says why not
        assert e.compensator or e.not_cancellable or e.leave_out, name
        # its other concerns are the effect's small objects, not the term's hooks
        assert e.drive_map is not None and e.drive_map.name == name, name
        assert not any(hasattr(term, h) for h in ("to_drive", "from_drive", "absent", "conceal", "leave_out")), name


def test_the_term_interface_is_the_diagnosis_only():
    """What a term offers is its columns, parameters and grid (and how it is searched and
    judged): the drive, compensator and study concerns live on the effect."""
    hooks = {k for k in dir(Term) if not k.startswith("_")}
    assert not hooks & {"to_drive", "from_drive", "absent", "in_drive", "leave_out", "effect", "conceal"}


def test_the_term_is_a_feature_library_and_three_capabilities():
    """A term's own interface is a feature library's (name, doc, units, coefficients and
    parameters, columns, grid, bounds, and what derives from them); everything else is in
    one of three capability objects, each concern's attributes in one of them only."""
    own = {k for k in dir(Term) if not k.startswith("_")}
    caps = {k for k in own if isinstance(getattr(Term, k), Capability)}
    assert caps == {"path", "search", "judging"}
    assert own - caps == {"name", "doc", "units", "coefs", "thetas", "full", "grid", "bounds", "rows", "physical",
                          "from_physical", "unit"}  # fmt: skip
    members = [{k for c in type(getattr(Term, n)).__mro__[:-2] for k in vars(c) if not k.startswith("_")}
               for n in sorted(caps)]  # fmt: skip
    assert sum(map(len, members)) == len(set().union(*members))  # no member in two capabilities
    assert not set().union(*members) & own


def test_a_capability_is_bound_to_the_term_that_carries_it():
    """A term reads its capability bound to itself (``self.term``), each term its own, the
    shared default included; a capability refuses a value it does not declare."""
    viscous, drift = physics.VOCABULARY["viscous_friction"], physics.VOCABULARY["drift"]
    assert viscous.search.term is viscous and physics.VOCABULARY["offset"].search.term is physics.VOCABULARY["offset"]
    assert viscous.search is viscous.search  # bound once
    assert type(viscous.search) is Search and drift.search.requires == ("offset",) and not drift.search.gated
    assert Term.search.term is None  # the class's own, unbound
    with pytest.raises(TypeError, match="no value 'screen'"):
        Search(screen=lambda *a: None)
    with pytest.raises(TypeError, match="no value 'colour'"):
        Judging(colour="red")
    assert SignalPath(kind="input", path_order=3).path_order == 3


def test_a_term_with_only_what_its_author_writes_is_complete():
    """The minimum of base.py's docs (name, coefs, units, full) makes a usable term."""

    class Minimal(Term):
        name, coefs, units = "minimal", ("c",), {"c": "F"}

        def full(self, d, theta, u_eff):
            return np.ones(4)

    t = Minimal()
    assert t.grid(None, None) == [{}] and t.path.kind == "column" and t.search.requires == ()
    assert t.bounds(None, None) == {} and not t.search.screening and t.search.eligible(_NoModel()) is None
    assert t.physical({}, (2.5,)) == {"c": 2.5} and t.from_physical({"c": 2.5}) == ({}, (2.5,))
    assert t.unit("c", "N") == "N" and t.judging.note({"c": -1.0}) == "" and t.judging.implausible({"c": 1.0}) == ""


class _NoModel:
    """A model that holds no term."""

    def has(self, name):
        return False

    has_free = has


def test_the_simulated_drive_sets_every_drive_field_once():
    d = {k: v for k, v in dataclasses.asdict(DriveConfig()).items()}
    fields = {k for k, _ in physics.drive_fields()}
    out = physics.simulated_drive(d, Simulation({}, 2.0, 1.0))
    assert set(out) == fields
    assert out["stroke"] == 2.0 and out["input_delay_s"] == 0.0 and out["mode_hz"] == []
    assert out["Ha"] == out["sigma"] == 1e-12  # no fitted hysteresis: a negligible Dahl element
    DriveConfig(**out, substeps=2)  # a valid drive


def test_each_diagnosis_stage_names_one_term():
    for stage in ("lattice", "breakaway", "frf"):
        assert physics.diagnosed_by(stage) in physics.VOCABULARY
    with pytest.raises(ValueError):
        physics.diagnosed_by("no such stage")


def test_the_compensator_terms_come_from_the_effects_in_stage_order():
    c = Config().compensator
    d = dataclasses.asdict(DriveConfig(Fc=1e-4, Fs=2e-4, b_asymmetry=0.1, cogging=1e-4, kf_linear=0.1))
    terms = physics.cancel_terms(d, Cancelling(), c)
    names = [n for n, _ in terms]
    assert names[0] == EQ9 and list(terms[0][1]) == ["B", "K", "h0"]
    assert names[1].startswith("Dahl hysteresis")
    assert names.index("asymmetric viscous friction") < names.index(
        "Coulomb friction beyond the Dahl element with its Stribeck rise") < names.index("force periodic in position")
    section = {k: v for _, keys in terms for k, v in keys.items()}
    from_dict({"compensator": section})  # every field a valid compensator field
    owners = {physics.owner("compensator", k).name for k in section if physics.owner("compensator", k) is not None}
    assert all(physics.EFFECTS[n].cancel is not None or n == "stribeck_friction" for n in owners)
    paper = [n for n, _ in physics.cancel_terms(d, Cancelling(paper=True), c)]
    assert paper == [EQ9, "sliding friction (eq. 9: Coulomb and its Dahl element)"]


def test_input_terms_are_ordered_along_the_input_path():
    inputs = sorted((t for t in physics.VOCABULARY.values() if t.path.kind == "input"), key=lambda t: t.path.path_order)
    assert [t.name for t in inputs] == ["input_saturation", "dead_zone", "time_delay", "sensor_lag"]


def test_docs_model_effects_table_is_current():
    text = (ROOT / "docs" / "model.md").read_text()
    m = re.search(r"<!-- effects: generated by servo.physics.markdown_table\(\) -->\n(.*?)<!-- end effects -->", text, re.S)
    assert m and m.group(1) == physics.markdown_table() + "\n"


def test_docs_diagnosis_vocabulary_table_matches_the_terms():
    """Every term a diagnosis names has its row in docs/diagnosis.md section 3, and the
    row names its coefficients and nonlinear parameters."""
    text = (ROOT / "docs" / "diagnosis.md").read_text()
    section = text[text.index("## 3. The vocabulary"):text.index("**One home per term.**")]
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| `(\w+)` \|.*$", section, re.M)}
    assert set(rows) == set(physics.VOCABULARY)
    for name, term in physics.VOCABULARY.items():
        listed = set(re.findall(r"`(\w+)`", rows[name].split("|")[2]))
        assert set(term.thetas) <= listed, name
        assert not term.coefs or listed & (set(term.coefs) | set(term.units)), name


@pytest.mark.parametrize("old, new", sorted(physics.renamed_keys().items()))
def test_a_renamed_config_key_is_one_error_line_naming_the_new_key(tmp_path, old, new):
    section, key = old.split(".")
    assert key not in {f.name for f in documented(type(getattr(Config(), section)))}
    path = tmp_path / "old.toml"
    path.write_text(f"[{section}]\n{key} = 1e-3\n")
    r = subprocess.run([sys.executable, "-m", "servo", "config", "--config", str(path)], capture_output=True, text=True)
    assert r.returncode != 0 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [f"servo: error: config: {old} was renamed: write {section}.{new} (docs/config.md)"]
    # the new key takes the value the old one held
    assert getattr(from_dict({section: {new: 1e-3}}), section).__getattribute__(new) == 1e-3


def test_the_records_take_the_compensator_fields_of_the_effects():
    cfg = Config()
    rec = np.zeros(1, STAGE_PARAMS)
    physics.fill(rec, physics.stage_values(cfg.compensator))
    assert rec["B"][0] == cfg.compensator.B and rec["Ha"][0] == cfg.compensator.Ha
    assert rec["Fc"][0] == cfg.compensator.sliding_level and rec["coul_c"][0] == cfg.compensator.coulomb_extra


def test_docs_model_capability_table_names_every_member_and_no_other():
    """docs/model.md, "Its diagnosis term": each capability's row names its members
    (those a term may change) and nothing the capability does not have."""
    text = (ROOT / "docs" / "model.md").read_text()
    rows = dict(re.findall(r"^\| `(path|search|judging)` \(`\w+`\) \| [^|]+ \| ([^\n]+) \|$", text, re.M))
    assert set(rows) == {"path", "search", "judging"}
    for cap, row in rows.items():
        cls = type(getattr(Term, cap))
        members = {k for c in cls.__mro__[:-2] for k in vars(c) if not k.startswith("_")} - {"screening"}
        named = {m for m in re.findall(r"`(\w+)", row)}
        assert named <= members, (cap, named - members)
        assert members <= named, (cap, members - named)

"""Config: complete default, documented fields, errors that name the key."""
import tomllib
from dataclasses import fields
from pathlib import Path

import pytest

from servo.config import SECTIONS, Config, from_dict, load_config, to_dict, to_markdown, to_toml
from servo.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_default_is_the_paper_drive_at_50_khz():
    cfg = Config()
    d = cfg.drive
    assert cfg.run.sample_rate_hz == 50_000 and cfg.dt == 2e-5
    assert (d.J, d.B, d.sigma, d.Ha, d.alpha, d.K, d.h0) == (1e-3, 2e-3, 320.0, 1e-3, 1.0, 0.1, 2e-3)
    assert d.mode_hz == [3000.0, 4100.0, 5000.0, 7000.0, 12300.0, 16400.0]
    assert d.input_delay_s == 10e-6 and d.current_limit == 1.0 and d.stroke == 15e-3


def test_every_field_has_a_unit_and_a_doc():
    from servo.controllers import KINDS

    for cls in [*SECTIONS.values(), *(k.Section for k in KINDS.values())]:
        assert cls.__doc__.strip()
        for f in fields(cls):
            if f.name == "kinds":  # the controller's kind sections, each checked here
                continue
            assert f.metadata["unit"] and f.metadata["doc"], f.name


def test_each_controller_kind_has_its_own_section():
    cfg = from_dict({"controller": {"kind": "pi", "current_limit": 0.5, "pi": {"kp": 100.0}}})
    assert cfg.controller.pi.kp == 100.0 and cfg.controller.section.kp == 100.0
    assert cfg.controller.pi.ki == Config().controller.pi.ki  # the rest stays default
    assert cfg.replace(controller={"pi": {"ki": 1.0}}).controller.pi.kp == 100.0  # replace merges a kind's section
    assert "[controller.pi]" in to_toml(cfg) and "kp = 100.0" in to_toml(cfg)
    assert to_dict(cfg)["controller"]["pi"]["kp"] == 100.0


@pytest.mark.parametrize(
    "data, message",
    [
        ({"controller": {"kp": 1.0}}, "controller.kp belongs to the controller kind's section: write it under [controller.pi]"),
        ({"controller": {"kind": "fuzzy"}}, "controller.kind must be one of pi"),
        ({"controller": {"pid": {"kp": 1.0}}}, "unknown controller kind section 'controller.pid' (did you mean 'pi'?)"),
        ({"controller": {"pi": {"kpp": 1.0}}}, "unknown key 'controller.pi.kpp' (did you mean 'kp'?)"),
        ({"controller": {"pi": {"kp": -1.0}}}, "controller.pi.kp = -1.0 is out of range"),
    ],
)
def test_controller_sections_are_validated(data, message):
    with pytest.raises(ConfigError) as err:
        from_dict(data)
    assert message in str(err.value)


def test_documented_toml_round_trips():
    text = to_toml(Config())
    assert "# Dahl pre-sliding stiffness" in text and "[A/m]" in text
    assert from_dict(tomllib.loads(text)) == Config()


def test_docs_config_md_is_current():
    assert (ROOT / "docs" / "config.md").read_text() == to_markdown() + "\n"


@pytest.mark.parametrize(
    "doc,message",
    [
        ({"drive": {"sigmaa": 1.0}}, "unknown key 'drive.sigmaa' (did you mean 'sigma'?)"),
        ({"driev": {}}, "unknown section 'driev' (did you mean 'drive'?)"),
        ({"drive": {"sigma": "high"}}, "drive.sigma must be a number"),
        ({"drive": {"sigma": -1.0}}, "drive.sigma = -1.0 is out of range (> 0 and <= 1e+12, A/m)"),
        ({"drive": {"alpha": 11.0}}, "drive.alpha = 11.0 is out of range"),
        ({"run": {"seed": 1.5}}, "run.seed must be an integer"),
        ({"run": {"fast_path": 1}}, "run.fast_path must be true or false"),
        ({"controller": {"velocity_source": "psychic"}}, "controller.velocity_source must be one of auto, estimated"),
        ({"drive": {"mode_hz": [1.0, "x"]}}, "drive.mode_hz[1] must be a number"),
        ({"drive": {"mode_hz": [3000.0]}}, "must have the same length"),
        ({"drive": {"Fc": 2e-3, "Fs": 1e-3}}, "drive.Fs = 0.001 must be >= drive.Fc"),
        ({"drive": {"mode_hz": [30000.0] * 6}}, "above Nyquist"),
        ({"run": {"duration_s": 0.0}}, "run.duration_s = 0.0 is out of range"),
        ({"compensator": {"fast_off_speed": 1.0}}, "switch hysteresis"),
    ],
)
def test_bad_values_name_the_key(doc, message):
    with pytest.raises(ConfigError) as exc:
        from_dict(doc)
    assert message in str(exc.value)
    assert "\n" not in str(exc.value)


def test_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[drive\nsigma = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    good = tmp_path / "good.toml"
    good.write_text("[drive]\nsigma = 400.0\n[run]\nduration_s = 1\n")
    cfg = load_config(good)
    assert cfg.drive.sigma == 400.0 and cfg.run.duration_s == 1.0 and cfg.drive.Ha == 1e-3


def test_replace_validates():
    with pytest.raises(ConfigError):
        Config().replace(drive={"J": 0.0})
    assert to_dict(Config().replace(run={"seed": 9}))["run"]["seed"] == 9


@pytest.mark.parametrize("key,value", [("drive.K", 1e300), ("compensator.h0", -1e200), ("drive.J", 1e-300),
                                       ("drive.B", 1e13)])  # fmt: skip
def test_values_beyond_any_physical_magnitude_are_refused(key, value):
    """Issue 9.5/9.6: inside the old ranges ('> 0', 'any'), these drove the plant to NaN
    with exit 0, or leaked overflow warnings."""
    section, name = key.split(".")
    with pytest.raises(ConfigError, match=rf"config: {key} = .* (is beyond any physical value|is out of range)"):
        from_dict({section: {name: value}})


def test_servo_config_section_comments_are_whole_sentences():
    """They were cut at the first line break of the docstring, mid-sentence."""
    from servo.config import SECTIONS, to_toml

    text = to_toml()
    for name, cls in SECTIONS.items():
        lines = text.split(f"\n[{name}]\n")[0].splitlines()
        comment = []
        for line in reversed(lines):
            if not line.startswith("# ") or not line.strip("# "):
                break
            comment.insert(0, line[2:])
        joined = " ".join(comment)
        assert joined.endswith((".", ")")), (name, joined)
        assert joined == " ".join(cls.__doc__.strip().split("\n\n")[0].split())


def test_help_shows_no_doubled_percent_signs():
    import contextlib
    import io

    from servo.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        main(["fleet", "simulate", "--help"])
    assert "%%" not in out.getvalue() and "10%)" in out.getvalue()

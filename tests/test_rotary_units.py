"""A rotary axis: positions in rad (and torques in N*m) carried through identify, frf,
diagnose and compensate, in what they print and write.

The same recording is written twice as CSV, once with ``x [m]`` and once with ``x [rad]``
in its header: the equations are the same, so every number must be the same and only
the units differ, each position ``m`` of the linear one a ``rad`` (``A*s^2/m`` ->
``A*s^2/rad``, ``m/A`` -> ``rad/A``, ``m/s`` -> ``rad/s``), and no unit of the rotary
one names a metre.
"""
import json
import re

import numpy as np
import pytest

from servo.cli import main
from servo.errors import ConfigError
from servo.io.units import position_unit, substitute

#: a position unit's metre: ``m`` as a whole word that is not the metre of a torque ``N*m``
METRE = re.compile(r"(?<![\w*])m(?![\w])")


def test_substitute_replaces_whole_words_in_one_pass():
    assert substitute("A*s^2/m", "N*m", "rad") == "N*m*s^2/rad"
    assert substitute("F/m", "N*m", "rad", "F") == "N*m/rad"
    assert [substitute(t, "A", "rad") for t in ("m/s", "1/m^2", "mA", "-", "Hz", "s")] == ["rad/s", "1/rad^2", "mA", "-",
                                                                                          "Hz", "s"]  # fmt: skip
    assert substitute("A*s/m", "A", "m") == "A*s/m"
    assert position_unit(None, "rad") == "rad" and position_unit("m", "rad") == "m" and position_unit(None) == "m"
    with pytest.raises(ConfigError, match="'deg': expected one of m, rad"):
        position_unit(None, "deg")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """One synthetic drive's recording as ``lin.csv`` (x in m) and ``rot.csv`` (x in rad)."""
    from servo.fleet.synthetic import synthetic_drives, write_fleet

    d = tmp_path_factory.mktemp("rotary")
    write_fleet(d, synthetic_drives(1, 0, seed=3), 0.2)
    z = np.load(d / "drive0000.npz")
    data = np.column_stack([z["t"], z["u"], z["x"]])
    for name, unit in (("lin", "m"), ("rot", "rad")):
        np.savetxt(d / f"{name}.csv", data, delimiter=",", header=f"t [s],u [A],x [{unit}]", comments="", fmt="%.17g")
    return d


def _cli(capsys, *argv) -> str:
    capsys.readouterr()
    assert main([str(a) for a in argv] + ["--quiet"]) == 0
    return capsys.readouterr().out


def test_identify_writes_and_prints_rad(recordings, capsys):
    d = recordings
    out = {n: _cli(capsys, "identify", d / f"{n}.csv", "--out", d / f"id_{n}") for n in ("lin", "rot")}
    lin, rot = (json.loads((d / f"id_{n}" / "summary.json").read_text()) for n in ("lin", "rot"))
    assert (lin["position_unit"], rot["position_unit"]) == ("m", "rad")
    fl, fr = lin["fits"]["robust"], rot["fits"]["robust"]
    assert fr["params"] == fl["params"]  # the same numbers
    assert fr["units"] == {k: substitute(u, "A", "rad") for k, u in fl["units"].items()}
    assert fr["units"]["J"] == "A*s^2/rad" and fr["units"]["K"] == "A/rad"
    assert "A*s^2/rad" in out["rot"] and "A*s^2/m" in out["lin"]
    assert not any(METRE.search(u) for u in fr["units"].values())
    assert "A*s/rad" in (d / "id_rot" / "params_robust.csv").read_text()
    from servo.identify.identification import identify
    from servo.identify.plots import plot_acceleration
    from servo.io.recording import load_recording

    fig = plot_acceleration(identify(load_recording(d / "rot.csv"), "robust"), position_unit="rad")
    assert fig.axes[0].get_ylabel() == "acceleration (rad/s^2)"


def test_position_unit_option_overrides_the_file_and_is_checked(recordings, capsys):
    d = recordings
    _cli(capsys, "frf", d / "lin.csv", "--position-unit", "rad", "--force-unit", "N*m", "--out", d / "frf_opt")
    assert json.loads((d / "frf_opt" / "summary.json").read_text())["unit"] == "rad/(N*m)"
    assert main(["frf", str(d / "lin.csv"), "--position-unit", "deg", "--out", str(d / "frf_bad"), "--quiet"]) == 2
    assert "invalid choice: 'deg'" in capsys.readouterr().err and not (d / "frf_bad").exists()


def test_frf_is_in_rad_per_force_unit(recordings, capsys):
    from servo.io.frequency_response import load_frequency_responses

    d = recordings
    for n in ("lin", "rot"):
        _cli(capsys, "frf", d / f"{n}.csv", "--out", d / f"frf_{n}")
    lin, rot = (json.loads((d / f"frf_{n}" / "summary.json").read_text()) for n in ("lin", "rot"))
    assert (lin["unit"], rot["unit"]) == ("m/A", "rad/A")
    (rl,), (rr,) = (load_frequency_responses(d / f"frf_{n}" / "frf.npz").values() for n in ("lin", "rot"))
    assert rr.unit == "rad/A" and np.array_equal(rr.H, rl.H)
    assert "H in rad/A" in (d / "frf_rot" / "report.html").read_text()


@pytest.mark.slow  # two diagnoses and a compensator
def test_diagnose_and_compensate_carry_rad_and_newton_metres(recordings, capsys):
    d = recordings
    text = _cli(capsys, "diagnose", d / "rot.csv", "--force-unit", "N*m", "--no-plots", "--out", d / "diag_rot")
    _cli(capsys, "diagnose", d / "lin.csv", "--force-unit", "N", "--no-plots", "--out", d / "diag_lin")
    rot, lin = (json.loads((d / f"diag_{n}" / "report.json").read_text()) for n in ("rot", "lin"))
    assert (rot["recording"]["position_unit"], rot["recording"]["force_unit"]) == ("rad", "N*m")
    assert "positions in rad, forces in N*m" in text
    for tr, tl in zip(rot["final_model"]["terms"], lin["final_model"]["terms"]):
        assert tr["params"] == tl["params"]  # the same numbers
        assert tr["units"] == {k: substitute(u, "N*m", "rad", "N") for k, u in tl["units"].items()}, (tr, tl)
        assert not any(METRE.search(u) for u in tr["units"].values()), tr
    units = {k: u for t in rot["final_model"]["terms"] for k, u in t["units"].items()}
    assert units["J"] == "N*m*s^2/rad" and units["B"] == "N*m*s/rad" and units["Fc"] == "N*m"
    assert "J 0.00" in text and "N*m*s^2/rad" in text and not METRE.search(text.split("final model (")[1].replace("N*m", ""))
    page = (d / "diag_rot" / "report.html").read_text()
    assert "N*m*s^2/rad" in page and "positions in rad" in page

    out = _cli(capsys, "compensate", d / "diag_rot" / "report.json", "--set", "controller.current_limit=1000",
               "--out", d / "comp_rot")  # fmt: skip
    s = json.loads((d / "comp_rot" / "summary.json").read_text())
    assert (s["unit"], s["position_unit"]) == ("N*m", "rad")
    assert s["units"]["B"] == "N*m*s/rad" and s["units"]["K"] == "N*m/rad"
    assert not any(METRE.search(u) for u in s["units"].values()), s["units"]
    assert "rad/s" in out and "positions in rad" in out and " m/s" not in out
    assert s["check"] is None and "not checked" in s["check_note"]
    assert "positions in rad" in (d / "comp_rot" / "compensator.toml").read_text()

"""``servo identify``: EMPS through the command line, the simulated square wave, and bad
input as one line with nothing written."""
import json

import numpy as np
import pytest

from servo.cli import main
from tests.helpers import EMPS_MAT
from tests.test_cli import servo


@pytest.mark.slow
def test_identify_emps_from_the_command_line(tmp_path):
    out = tmp_path / "emps"
    r = servo("identify", str(EMPS_MAT), "--columns", "u=vir,x=qm", "--scale", "u=gtau", "--off", "K",
              "--emps-reference", "--force-unit", "N", "--out", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "relative error 4.083" in r.stdout
    s = json.loads((out / "summary.json").read_text())
    fit = s["fits"]["robust"]
    assert abs(fit["params"]["B"] - 203.5034) / 203.5034 < 0.005
    assert fit["units"]["J"] == "N*s^2/m"
    assert {"acceleration_robust.png", "force_fit_robust.png", "params_robust.csv", "rows_robust.csv"} <= {
        p.name for p in out.iterdir()
    }


@pytest.mark.slow
def test_identify_simulated_square_wave(tmp_path):
    """The square-wave experiment on the default drive (robust path, force aligned with
    the drive's known delay): J, B, Fc, h0 within 3 % of what model (3) can represent of
    the drive (its Dahl pivot projected on the regressor); J and h0 within 1 % of the
    drive's own values.  K is weakly excited and biased by the flexible modes (docs)."""
    out = tmp_path / "sq"
    r = servo("identify", "--simulate", "--duration", "0.5", "--path", "robust", "--out", str(out))
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    err = s["fits"]["robust"]["error_pct"]
    assert all(abs(err["model (3) of the drive"][k]) < 3 for k in ("J", "B", "Fc", "h0")), err
    assert abs(err["drive"]["J"]) < 1 and abs(err["drive"]["h0"]) < 1, err
    assert (out / "recording.csv").exists()


@pytest.mark.parametrize(
    "args,needle",
    [
        (["identify"], "give a RECORDING"),
        (["identify", "EMPS", "--columns", "u=vir"], "has no column 'x'"),
        (["identify", "EMPS", "--columns", "u=vir,x=qm", "--terms", "J,Q"], "unknown term 'Q'"),
        (["identify", "EMPS", "--columns", "u=vir,x=qm", "--path", "paper"], "needs a measured velocity"),
        (["identify", "EMPS", "--columns", "u=vir,x=qm", "--trim", "4"], "expected START,END"),
        (["identify", "EMPS", "--columns", "u=vir,x=qm", "--cutoff-hz", "900"], "between 0 and Nyquist"),
        (["identify", "CONST"], "nothing excited"),
        (["identify", "NAN"], "x is NaN or infinite at sample 7"),
    ],
)
def test_identify_bad_input(tmp_path, capsys, args, needle):
    const = tmp_path / "const.csv"
    t = np.arange(500) * 1e-3
    np.savetxt(const, np.column_stack([t, np.full_like(t, 1e-3), np.zeros_like(t)]), delimiter=",", header="t,u,x", comments="")
    nan = tmp_path / "nan.csv"
    rows = np.column_stack([t, np.sin(t), np.cos(t)])
    rows[7, 2] = np.nan
    np.savetxt(nan, rows, delimiter=",", header="t,u,x", comments="")
    names = {"EMPS": str(EMPS_MAT), "CONST": str(const), "NAN": str(nan)}
    out = tmp_path / "o"
    code = main([names.get(a, a) for a in args] + ["--out", str(out)])  # in process: fast
    err = capsys.readouterr().err
    assert code != 0
    assert err.count("\n") == 1 and err.startswith("servo: error:"), err
    assert needle in err, err
    assert not out.exists()


@pytest.mark.slow
def test_hysteresis_command_on_its_own_recording(tmp_path, capsys):
    """servo hysteresis --simulate writes the recording; the same command fits it back."""
    out = tmp_path / "sim"
    assert main(["hysteresis", "--simulate", "--duration", "1", "--out", str(out)]) == 0
    assert {"hysteresis_loop.png", "hysteresis_large.png", "summary.json"} <= {p.name for p in out.iterdir()}
    again = tmp_path / "rec"
    assert main(["hysteresis", str(out / "recording_small.csv"), "--out", str(again)]) == 0
    s = json.loads((again / "summary.json").read_text())
    assert abs(s["dahl"]["params"]["sigma"] - 320.0) / 320.0 < 0.02
    from servo.io.provenance import sha256_file

    src = str(out / "recording_small.csv")
    assert s["provenance"]["inputs"] == {src: sha256_file(src)} and s["provenance"]["config_sha256"] is None
    sim = json.loads((out / "summary.json").read_text())["provenance"]
    assert sim["command"][:3] == ["servo", "hysteresis", "--simulate"] and len(sim["config_sha256"]) == 64
    capsys.readouterr()
    assert main(["hysteresis", str(out / "recording_small.csv"), "--columns", "v=nope", "--out", str(tmp_path / "x")]) == 2
    assert "has no column 'nope'" in capsys.readouterr().err


@pytest.fixture(scope="module")
def square_wave_csv(tmp_path_factory):
    """A recording of large square-wave motion (the identify experiment): no pre-sliding loop."""
    out = tmp_path_factory.mktemp("sq")
    r = servo("identify", "--simulate", "--duration", "0.4", "--out", str(out))
    assert r.returncode == 0, r.stderr
    return out / "recording.csv"


@pytest.mark.slow
@pytest.mark.parametrize(
    "args,needle",
    [
        (["hysteresis", "{rec}"], "the Dahl fit cannot be trusted: sigma, Ha, alpha, c not identifiable"),
        (["hysteresis", "{rec}", "--deadband", "-1"], "direction deadband must be a speed >= 0 m/s"),
        (["identify", "{rec}", "--force-lag", "1e9"], "force lag 1e+09 s is more than 10% of the recording"),
    ],
)
def test_a_result_that_cannot_be_trusted_is_an_error_not_a_success(square_wave_csv, args, needle, tmp_path):
    """Issue 9.5: these were reported as results (+- inf, 'Infinity' in summary.json, a
    relative error of 0.0000 %, a negative deadband accepted)."""
    out = tmp_path / "o"
    r = servo(*[a.format(rec=square_wave_csv) for a in args], "--out", str(out))
    assert r.returncode == 2, r.stdout + r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("servo: error:") and needle in r.stderr, r.stderr
    assert not out.exists()

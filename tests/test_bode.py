"""Swept-sine Bode on the default drive (paper Fig. 7-8): a small sweep, still meaningful.

Without compensation the low-frequency resonance falls and its damping rises with the
input level; with compensation the levels agree within 1 dB below the first flexible
mode, the slope is -40 +- 2 dB/decade and the phase -180 +- 10 degrees."""
import numpy as np
import pytest

from servo.config import Config
from servo.experiments.bode import SweepSettings, sine_point, sweep
from servo.experiments.bode_analysis import band_max, linearity, loop_delay, resonance
from tests.helpers import NO_MODES, quiet_config

LEVELS = (0.2e-3, 1e-3, 4e-3, 16e-3)


@pytest.fixture(scope="module")
def sweeps():
    cfg = Config()
    s = SweepSettings(levels=LEVELS, f_min=30.0, f_max=1000.0, n_freq=8, periods=4, settle_periods=3, settle_s=0.02)
    return cfg, {comp: [sweep(cfg, lev, s, comp) for lev in LEVELS] for comp in (False, True)}


def test_uncompensated_resonance_falls_and_damping_rises_with_level(sweeps):
    cfg, res = sweeps
    r = [resonance(sw, delay_s=loop_delay(cfg)) for sw in res[False]]
    f_n = [x["f_n_hz"] for x in r]
    zeta = [x["zeta"] for x in r]
    assert all(a > b for a, b in zip(f_n, f_n[1:])), f_n
    assert all(a < b for a, b in zip(zeta, zeta[1:])), zeta
    # small level: the pivot is the Dahl spring, sqrt(sigma/J)/(2 pi) = 90 Hz
    assert f_n[0] == pytest.approx(np.sqrt(cfg.drive.sigma / cfg.drive.J) / (2 * np.pi), rel=0.05)
    assert linearity(res[False], band_max(cfg))["spread_db_max"] > 10  # really nonlinear


def test_compensated_plant_is_a_double_integrator_at_every_level(sweeps):
    cfg, res = sweeps
    lin = linearity(res[True], band_max(cfg))
    assert lin["spread_db_max"] <= 1.0, lin
    assert all(abs(s + 40) <= 2 for s in lin["slope_db_per_decade"].values()), lin
    assert -190 <= lin["phase_deg_min"] and lin["phase_deg_max"] <= -170, lin


def test_sine_point_matches_a_known_linear_plant():
    """On a linear drive (pivot made negligible, no modes, no noise) the estimate equals
    the exact double integrator with its delay, and the coherence is 1."""
    cfg = quiet_config(**NO_MODES, Ha=1e-8, sigma=1e-3, K=0.0, B=0.0).replace(controller={"pi": dict(kp=50.0, ki=100.0, kd=0.5)})
    s = SweepSettings(periods=4, settle_periods=3)
    f, H, std, coh, _ = sine_point(cfg, 200.0, 1e-3, s, compensation=False)
    w = 2 * np.pi * f
    # pivot force <= 10 nA: a double integrator, delayed
    expected = -1.0 / (cfg.drive.J * w**2) * np.exp(-1j * w * loop_delay(cfg))
    assert abs(H / expected - 1) < 0.01
    assert coh > 0.999


def test_bode_command_writes_csv_frd_and_plots(tmp_path, capsys):
    import control

    from servo.cli import main
    from servo.io.frequency_response import load_frequency_responses

    out = tmp_path / "b"
    assert main(["bode", "--levels", "1,4", "--n-freq", "3", "--periods", "2", "--f-min", "100", "--f-max", "300",
                 "--no-second-drive", "--out", str(out)]) == 0  # fmt: skip
    printed = capsys.readouterr()
    assert "equivalent resonance" in printed.out  # progress on stderr: tests/test_progress.py
    assert not (out / "frd.pkl").exists()  # no pickle tied to a python-control version
    resp = load_frequency_responses(out / "frd.npz")
    assert len(resp) == 4 and all(r.unit == "m/A" and r.f_hz.size == 3 for r in resp.values())
    frds = {k: r.to_control() for k, r in resp.items()}
    assert all(isinstance(f, control.FrequencyResponseData) for f in frds.values())
    rows = np.loadtxt(out / "bode.csv", delimiter=",", skiprows=1)
    assert rows.shape == (12, 11)
    # the file holds the very numbers of the table, by label
    first = next(iter(resp.values()))  # "drive, ...": drive code 0 in the table
    row = rows[(rows[:, 0] == 0) & (rows[:, 1] == first.meta["compensation"]) & (rows[:, 2] == first.meta["level_A"])]
    np.testing.assert_allclose(first.H, row[:, 6] + 1j * row[:, 7], rtol=1e-12)
    np.testing.assert_allclose(first.rel_std * np.abs(first.H), row[:, 8], rtol=1e-12)
    assert {"bode_compensated.png", "bode_uncompensated.png", "summary.json"} <= {p.name for p in out.iterdir()}
    import json

    prov = json.loads((out / "summary.json").read_text())["provenance"]
    assert prov["command"][:2] == ["servo", "bode"] and prov["libraries"]["control"] == control.__version__
    assert main(["bode", "--levels", "1,x", "--out", str(tmp_path / "bad")]) == 2
    assert "expected comma-separated numbers" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()


def test_an_unstable_holding_loop_is_refused():
    """Halving the 7 kHz mode's damping destabilises the default holding loop: refused."""
    from servo.errors import ConfigError
    from servo.experiments.bode import check_holding_loop

    cfg = Config()
    zeta = list(cfg.drive.mode_zeta)
    zeta[3] *= 0.5
    with pytest.raises(ConfigError, match=r"holding loop is unstable.*oscillating at (69|70)\d\d Hz"):
        check_holding_loop(cfg.replace(drive={"mode_zeta": zeta}))
    check_holding_loop(cfg)  # the default drive is fine

"""servo run's excitation scenarios: the signals of servo.scenarios.excitation, on both
paths, bit for bit; and what they are for, a frequency response of the drive."""
import numpy as np
import pytest

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.errors import ConfigError
from servo.runtime.closedloop import MemoryLog
from servo.frf.estimate import WelchSettings, instrumental
from servo.io.runlog import RunLog
from servo.scenarios import excitation as excite
from servo.runtime.controller import Controller
from servo.runtime.loop import log_rows, run_closed_loop
from servo.scenarios import scenario_inputs
from servo.runtime.simdriver import SimDriver

C = {c: i for i, c in enumerate(LOG_COLUMNS)}
QUIET = {"step_times": [], "step_positions": [], "disturbance_amplitude": 0.0}


def _run(cfg, fast, tmp_path=None, comp=True):
    inputs = scenario_inputs(cfg)
    log = MemoryLog(log_rows(cfg)) if tmp_path is None else RunLog(tmp_path, f"l{int(fast)}", LOG_COLUMNS)
    with SimDriver(cfg, inputs) as drv:
        run_closed_loop(cfg, drv, Controller(cfg, compensation=comp), inputs, log, fast=fast, timing=False)
    if tmp_path is None:
        return log.data[: log.rows]
    log.close()
    return log.recorded()


@pytest.mark.parametrize("kind", ["chirp", "multisine", "prbs"])
def test_each_excitation_is_its_generator_from_its_start_on_both_paths_bit_for_bit(kind, tmp_path):
    cfg = Config().replace(run={"duration_s": 0.1, "excitation_every": 3},
                           scenario={"excitation": kind, "excitation_start": 0.01, "excitation_period": 0.02})  # fmt: skip
    fast, ticks = _run(cfg, True), _run(cfg, False, tmp_path)
    assert np.array_equal(fast, ticks)
    s, dt, n = cfg.scenario, cfg.dt, cfg.n_ticks
    k0 = int(round(s.excitation_start / dt))
    if kind == "chirp":
        expect = excite.chirp(n - k0, dt, s.excitation_f_min, s.excitation_f_max, s.excitation_amplitude)
    elif kind == "multisine":
        expect = excite.multisine(n - k0, dt, s.excitation_f_min, s.excitation_f_max, s.excitation_amplitude,
                                  period=int(round(s.excitation_period / dt)))  # fmt: skip
    else:
        expect = None
    u = fast[:, C["u_exc"]]
    held = np.arange(n) - np.arange(n) % 3  # the excitation task runs every 3 ticks and holds
    assert np.all(u[:k0] == 0.0) and np.max(np.abs(u)) == pytest.approx(s.excitation_amplitude)
    if expect is not None:
        full = np.concatenate([np.zeros(k0), expect])
        np.testing.assert_allclose(u, full[held], rtol=0, atol=1e-12 * s.excitation_amplitude)
    else:
        assert set(np.unique(u[k0 + 3:])) == {-s.excitation_amplitude, s.excitation_amplitude}


def test_a_multisine_run_measures_the_compensated_drive_as_a_double_integrator():
    """The paper's claim, measured the way a lab would: inject a multisine, estimate
    u_n -> x (the current the controller asks for; the compensator's u_c cancels the
    pivot) with the excitation as instrument (the loop is closed), and compare with
    1/(J w^2) below the flexible modes, at every coherent line of the band."""
    cfg = Config().replace(run={"duration_s": 2.0},
                           scenario={**QUIET, "excitation": "multisine", "excitation_f_min": 20.0,
                                     "excitation_f_max": 500.0, "excitation_period": 0.2,
                                     "excitation_amplitude": 2e-3})  # fmt: skip
    a = _run(cfg, True)[10_000:]  # one period of transient dropped
    resp = instrumental(a[:, C["u_exc"]], a[:, C["u_n"]], a[:, C["x"]], cfg.dt,
                        WelchSettings(nperseg=10_000, overlap=0.0, window="boxcar"))  # fmt: skip
    f = resp.f_hz
    m = (f >= 20) & (f <= 500) & (resp.coherence > 0.9)
    assert m.sum() >= 90  # nearly every excited line (5 Hz apart) is coherent
    ratio = np.abs(resp.H[m]) * cfg.drive.J * (2 * np.pi * f[m]) ** 2
    assert np.all(np.abs(ratio - 1) < 0.05), (ratio.min(), ratio.max())
    assert np.all(np.abs(np.degrees(np.angle(-resp.H[m]))) < 6.0)  # -180 degrees


def test_bad_excitation_settings_are_one_line():
    with pytest.raises(ConfigError, match="excitation"):
        Config().replace(scenario={"excitation": "noise"})
    with pytest.raises(ConfigError, match="Nyquist|f_max|above"):
        scenario_inputs(Config().replace(scenario={"excitation": "chirp", "excitation_f_max": 40_000.0}))
    with pytest.raises(ConfigError, match="shorten it"):
        scenario_inputs(Config().replace(run={"sample_rate_hz": 1e6}, scenario={"excitation": "multisine",
                                                                                "excitation_period": 5.0}))

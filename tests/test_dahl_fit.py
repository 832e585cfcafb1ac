"""Dahl fit (eq. 6-7): exact on noise-free synthetic loops, within tolerance with noise,
and the simulated drive's hysteresis experiments recover the drive's parameters."""
import numpy as np
import pytest

from servo.config import Config
from servo.experiments.hysteresis import HysteresisExperiment, average_slope, run_large_loop, run_small_loop
from servo.identify.dahl_fit import dahl_response, fit_dahl
from servo.identify.regressors import IdentificationError

TRUE = {"sigma": 320.0, "Ha": 1e-3, "alpha": 1.0, "c": 2e-3}


def synthetic_loop(alpha=1.0, n=20000):
    t = np.linspace(0, 2, n)
    x = 4e-6 * np.sin(np.pi * t / 2) * np.sin(2 * np.pi * 5 * t)
    v = np.gradient(x, t)
    H = dahl_response(x, v, TRUE["sigma"], TRUE["Ha"], alpha)
    return x, v, H + TRUE["c"]


@pytest.mark.parametrize("alpha", [1.0, 1.6])
def test_noise_free_fit_is_exact(alpha):
    x, v, u = synthetic_loop(alpha)
    fit = fit_dahl(x, v, u)
    truth = dict(TRUE, alpha=alpha)
    for k in truth:
        assert fit.params[k] == pytest.approx(truth[k], rel=1e-5), k
    assert fit.rel_error_pct < 1e-4


def test_noisy_fit_within_tolerance():
    """Current noise 2 % of the loop's range: sigma, Ha, alpha within 2 %."""
    x, v, u = synthetic_loop()
    rng = np.random.default_rng(3)
    u_noisy = u + 0.02 * np.ptp(u) * rng.standard_normal(u.size)
    fit = fit_dahl(x, v, u_noisy)
    for k in ("sigma", "Ha", "alpha"):
        assert fit.params[k] == pytest.approx(TRUE[k], rel=0.02), k
        assert abs(fit.params[k] - TRUE[k]) < 5 * fit.std[k] + 1e-3 * TRUE[k]


def test_no_reversal_is_refused():
    x = np.linspace(0, 1e-5, 1000)
    with pytest.raises(IdentificationError, match="needs velocity reversals"):
        fit_dahl(x, np.ones_like(x), 1e-3 * np.ones_like(x))


def test_simulated_drive_hysteresis_experiments():
    """Paper Fig. 3-4 on the default drive: the fit recovers sigma, Ha, alpha within 2 %,
    and the large loop's average slope is the drive's bias stiffness K within 3 %."""
    cfg = Config()
    exp = HysteresisExperiment(duration_s=1.0, hz=5.0, large_cycles=1.0)
    small = run_small_loop(cfg, exp)
    fit = fit_dahl(small["x"], small["v"], small["u"], deadband=cfg.controller.direction_deadband)
    d = cfg.drive
    assert fit.params["sigma"] == pytest.approx(d.sigma, rel=0.02)
    assert fit.params["Ha"] == pytest.approx(d.Ha, rel=0.02)
    assert fit.params["alpha"] == pytest.approx(d.alpha, rel=0.02)
    large = run_large_loop(cfg, exp)
    slope = average_slope(large["t"], large["x"], large["v"], large["u"], cfg.dt)
    assert slope["K"] == pytest.approx(d.K, rel=0.03)
    assert slope["Fc"] == pytest.approx(d.Ha, rel=0.05)

"""With exact parameters the compensated plant is a double integrator (paper eq. 10)."""
import numpy as np
import pytest

from kernels.plant import plant_measure, plant_step
from servo.runtime.controller import Controller
from servo.runtime.simplant import build_plant
from tests.helpers import NO_MODES, quiet_config


def drive_open_loop(u_n: np.ndarray, compensation: bool):
    """Apply the nominal input ``u_n`` (A) through the controller with the holding loop
    switched off (gains 0) to a noise-free drive without modes or delay.  Returns the
    measured positions (n+1,) and the nominal inputs the controller actually applied."""
    cfg = quiet_config(**NO_MODES, input_delay_s=0.0).replace(controller={"pi": dict(kp=0.0, ki=0.0, kd=0.0)})
    return (*drive_open_loop_cfg(cfg, u_n, compensation), cfg)


def drive_open_loop_cfg(cfg, u_n: np.ndarray, compensation: bool | None = None):
    """:func:`drive_open_loop` on the drive and compensator of ``cfg``: ``(xs, un)``."""
    p = build_plant(cfg.drive, cfg.dt)
    ctl = Controller(cfg, compensation=compensation)
    xs, un = np.zeros(len(u_n) + 1), np.zeros(len(u_n))
    for k in range(len(u_n)):
        x, v = plant_measure(p.state, p.params, p.q, p.gain, 0.0, 0.0)
        if k == 0:
            ctl.start(x, v, p.u_hold)
        xs[k] = x
        u = ctl.tick(x, v, 0.0, u_n[k])
        un[k] = ctl.stage_state[0]["u_n"] - ctl.state[0]["integ"]  # the excitation part of u_n
        plant_step(p.state, p.params, p.q, p.mab, p.ubuf, u, 0.0)
    xs[-1] = plant_measure(p.state, p.params, p.q, p.gain, 0.0, 0.0)[0]
    return xs, un


def acceleration_error(xs, un, cfg) -> float:
    """RMS of (measured second difference - double-integrator prediction), relative to
    the prediction: for x'' = u_n/J under a zero-order hold,
    x[k+1] - 2 x[k] + x[k-1] = dt^2 (u_n[k] + u_n[k-1]) / (2 J) exactly."""
    dt, J = cfg.dt, cfg.drive.J
    measured = xs[2:] - 2 * xs[1:-1] + xs[:-2]
    predicted = dt * dt * (un[1:] + un[:-1]) / (2 * J)
    return float(np.sqrt(np.mean((measured - predicted) ** 2)) / np.sqrt(np.mean(predicted**2)))


@pytest.mark.parametrize(
    "name,u_n",
    [
        # small motion (sub-micron, Dahl regime): 0.3 mA at 100 Hz
        ("small", 0.3e-3 * np.sin(2 * np.pi * 100 * np.arange(10000) * 2e-5)),
        # large motion (sliding, eq. 3 regime): 5 mA square wave at 20 Hz
        ("large", 5e-3 * np.sign(np.sin(2 * np.pi * 20 * np.arange(10000) * 2e-5 + 0.1))),
    ],
)
def test_compensated_plant_is_a_double_integrator(name, u_n):
    xs, un, cfg = drive_open_loop(u_n, compensation=True)
    assert acceleration_error(xs, un, cfg) < 0.01
    xs_raw, un_raw, _ = drive_open_loop(u_n, compensation=False)
    assert acceleration_error(xs_raw, un_raw, cfg) > 0.1  # the pivot is really there (21 % and 200 %)


def test_compensated_response_is_amplitude_independent():
    """Paper Fig. 8 in the time domain: scaling u_n by 30 scales the motion by 30."""
    base = 0.2e-3 * np.sin(2 * np.pi * 150 * np.arange(6000) * 2e-5)
    xs_small, _, _ = drive_open_loop(base, compensation=True)
    xs_large, _, _ = drive_open_loop(30 * base, compensation=True)
    small, large = xs_small - xs_small[0], (xs_large - xs_large[0]) / 30
    assert np.abs(small - large).max() < 0.02 * np.abs(large).max()
    raw_small, _, _ = drive_open_loop(base, compensation=False)
    raw_large, _, _ = drive_open_loop(30 * base, compensation=False)
    rs, rl = raw_small - raw_small[0], (raw_large - raw_large[0]) / 30
    assert np.abs(rs - rl).max() > 0.3 * np.abs(rl).max()

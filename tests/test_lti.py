"""python-control as the lingua franca: every controller kind, the drive's linear part,
an identified model and a config's drive convert to python-control systems whose
responses are servo's own; their margins are ``servo loop``'s; FRFs and systems
round-trip through python-control, MATLAB .mat and HDF5."""
from __future__ import annotations

import json

import control
import numpy as np
import pytest

from servo import lti
from servo.config import Config
from servo.io.frequency_response import FrequencyResponse, load_frequency_responses, save_h5, save_mat, save_npz
from servo.loop.design import controller_response, loop_design, plant_response
from servo.design.margins import margins

KINDS = {
    "pi": Config().replace(controller={"velocity_source": "estimated"}),  # the rate from the estimator: exact
    "pi measured velocity": Config(),
    "track": Config().replace(controller={"kind": "track"}),
    "nss": Config().replace(controller={"kind": "nss"}, run={"sample_rate_hz": 52800.0}),
}
F = np.geomspace(10.0, 20_000.0, 300)


def at(sys, cfg, f=F):
    return sys(np.exp(2j * np.pi * f * cfg.dt))


@pytest.mark.parametrize("name", KINDS)
def test_each_controller_kind_is_a_discrete_system_with_its_own_response(name):
    cfg = KINDS[name]
    C = lti.controller(cfg)
    assert isinstance(C, control.StateSpace) and C.dt == pytest.approx(cfg.dt)
    rel = np.abs(at(C, cfg) / controller_response(cfg, F) - 1)
    if name == "pi measured velocity":  # the measured velocity read as a backward difference:
        half_sample = np.pi * F * cfg.dt  # its error, w*dt/2, bounds the controller's
        assert np.all(rel[F <= 5000] <= half_sample[F <= 5000])
    else:
        assert np.all(rel < 1e-9), rel.max()


@pytest.mark.parametrize("compensated", [True, False])
def test_the_drive_is_its_sampled_plant_with_the_delay_exact(compensated):
    cfg = Config().replace(drive={"input_delay_s": 27e-6}, link={"command_latency_ticks": 1})
    P = lti.drive(cfg, compensated=compensated, stiffness=0.0 if compensated else cfg.drive.sigma)
    assert P.dt == pytest.approx(cfg.dt)
    ref = plant_response(cfg, F, "drive", compensated)
    np.testing.assert_allclose(at(P, cfg), ref, rtol=1e-9)
    Pc = lti.drive(cfg, discrete=False, compensated=compensated, stiffness=0.0 if compensated else cfg.drive.sigma)
    assert Pc.dt == 0 and Pc.nstates == 2 + 2 * len(cfg.drive.mode_hz)


def _near(a, b, tol):
    return any(abs(x - b) <= tol for x in a)


@pytest.mark.parametrize("name", KINDS)
def test_python_control_margins_are_servo_loops(name):
    """Every crossing ``servo loop`` reports for the designed loop (its band, 20-2000 Hz)
    is one python-control finds on the LTI loop, with the same margin."""
    cfg = KINDS[name]
    d = loop_design(cfg, np.geomspace(20.0, 2000.0, 1200), "drive", True)
    ours = margins(d.f_hz, d.L, dense=True)
    gm, pm, _, w180, wc, _ = control.stability_margins(lti.loop(cfg), returnall=True, method="frd")
    fc, f180 = np.atleast_1d(wc) / (2 * np.pi), np.atleast_1d(w180) / (2 * np.pi)
    pm_tol = 0.5 if name == "pi measured velocity" else 0.01  # deg
    assert ours["crossovers_hz"]
    for f, p in zip(ours["crossovers_hz"], ours["phase_margins_deg"]):
        i = int(np.argmin(np.abs(fc - f)))
        assert abs(fc[i] - f) < 0.005 * f and abs(np.atleast_1d(pm)[i] - p) < pm_tol, (f, p, fc, pm)
    for f, g in ((m["hz"], m["db"]) for m in ours["gain_margins"]):
        i = int(np.argmin(np.abs(f180 - f)))
        assert abs(f180[i] - f) < 0.005 * f and abs(20 * np.log10(np.atleast_1d(gm)[i]) - g) < 0.1


def test_a_kind_without_a_linear_form_is_one_line(monkeypatch):
    from servo.controllers.base import ControllerKind
    from servo.controllers.pi import PI
    from servo.errors import ConfigError

    with pytest.raises(NotImplementedError):
        ControllerKind.to_control(None, Config())  # optional for a plug-in kind
    monkeypatch.setattr(PI, "to_control", classmethod(ControllerKind.to_control.__func__))
    with pytest.raises(ConfigError, match="'pi' has no linear form"):
        lti.controller(Config())


def test_an_identified_model_and_a_config_drive_are_their_linear_parts(tmp_path):
    from servo.cli import main

    assert main(["identify", "--simulate", "--duration", "0.5", "--quiet", "--out", str(tmp_path / "id")]) == 0
    q = json.loads((tmp_path / "id" / "summary.json").read_text())["fits"]["robust"]["params"]
    G = lti.model(tmp_path / "id" / "summary.json")
    s = 2j * np.pi * F
    np.testing.assert_allclose(G(s), 1 / (q["J"] * s**2 + q["B"] * s + q["K"]), rtol=1e-9)
    assert G.input_labels == ["u (A)"] and G.dt == 0
    (tmp_path / "drive.toml").write_text("[drive]\nJ = 2e-3\nB = 0.01\nK = 0.5\nmode_hz = [3000.0]\n"
                                         "mode_zeta = [0.02]\nmode_gain = [0.5]\n")  # fmt: skip
    D = lti.model(tmp_path / "drive.toml")
    w0 = 2 * np.pi * 3000.0
    rigid = 1 / (2e-3 * s**2 + 0.01 * s + 0.5)
    np.testing.assert_allclose(D(s), rigid + 0.5 / 2e-3 / (s**2 + 2 * 0.02 * w0 * s + w0**2), rtol=1e-9)


def test_systems_round_trip_through_mat_and_hdf5(tmp_path):
    cfg = KINDS["track"]
    systems = {"controller": lti.controller(cfg), "drive": lti.drive(cfg), "drive continuous": lti.drive(cfg, False)}
    for suffix in (".mat", ".h5"):
        back = lti.load(lti.export(tmp_path / f"sys{suffix}", systems))
        for name, sys in systems.items():
            got = back[lti._mat_name(name)] if suffix == ".mat" else back[name]
            assert (got.dt or 0) == pytest.approx(sys.dt or 0)
            s = np.exp(2j * np.pi * F * cfg.dt) if sys.dt else 2j * np.pi * F
            np.testing.assert_allclose(got(s), sys(s), rtol=1e-12)


def test_frequency_responses_round_trip_through_python_control_mat_hdf5(tmp_path):
    cfg = KINDS["track"]
    frd = control.FrequencyResponseData(at(lti.loop(cfg), cfg), 2 * np.pi * F)
    r = FrequencyResponse.from_control(frd, unit="-", meta={"what": "L"})
    np.testing.assert_allclose(r.f_hz, F, rtol=1e-15)
    np.testing.assert_array_equal(r.to_control()(2j * np.pi * F), frd(2j * np.pi * F))
    r.coherence[:] = np.linspace(0, 1, F.size)
    for save, name in ((save_npz, "r.npz"), (save_mat, "r.mat"), (save_h5, "r.h5")):
        (label, back), = load_frequency_responses(save(tmp_path / name, {"L, track": r})).items()
        assert label == "L, track" and back.unit == "-" and back.meta == {"what": "L"}
        np.testing.assert_array_equal(back.H, r.H)
        np.testing.assert_array_equal(back.f_hz, r.f_hz)
        np.testing.assert_array_equal(back.coherence, r.coherence)


@pytest.mark.parametrize("name", ["pi", "track"])
def test_the_loop_on_the_board_has_no_link_latency_in_its_design(name):
    """``link.loop = "board"``: the command never crosses the link, so every design-side
    figure (the sampled plant, servo loop's margins, python-control's loop, the delays
    the Bode and square-wave experiments fit) equals that of the same config with latency
    0, and the host-closed loop with the same latency differs."""
    from servo.experiments.bode_analysis import loop_delay
    from servo.experiments.square_wave import force_lag

    base = Config().replace(controller={"kind": name})
    board = base.replace(link={"loop": "board", "command_latency_ticks": 3, "batch": 4})
    none = base.replace(link={"command_latency_ticks": 0})
    host = base.replace(link={"command_latency_ticks": 3})
    assert (board.link.loop_latency_ticks, none.link.loop_latency_ticks, host.link.loop_latency_ticks) == (0, 0, 3)
    f = np.geomspace(20.0, 2000.0, 600)

    def figures(cfg):
        d = loop_design(cfg, f, "drive", True)
        m = margins(d.f_hz, d.L, dense=True)
        gm, pm = control.stability_margins(lti.loop(cfg))[:2]
        return d.L, m["phase_margins_deg"], (gm, pm), lti.drive(cfg).A.shape, loop_delay(cfg), force_lag(cfg)

    fb, fn, fh = figures(board), figures(none), figures(host)
    assert np.array_equal(fb[0], fn[0]) and fb[1:] == fn[1:]
    assert not np.allclose(fh[0], fn[0]) and fh[1] != fn[1] and fh[4] > fn[4] and fh[3] != fn[3]

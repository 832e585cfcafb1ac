"""The "nss" controller kind is the NSS HDD benchmark's own reference design, checked
against the benchmark package's files (../shared/data/nss-hdd-benchmark/): the controller
of ``example1/followdemo.m`` rebuilt from its matrices, stability on all 54 perturbed
plants, and the written-in runout ``RROSequence.mat`` in the disturbance model."""
import re

import control
import numpy as np
import pytest
from scipy import signal

from servo.config import Config, load_config
from servo.controllers.nss import NSSSection
from servo.design import loop, sections
from servo.design.reference import NSS_NOTCHES
from servo.errors import ConfigError
from servo.hdd.benchmark import benchmark
from servo.hdd.disturbances import generate, written_in_rro
from servo.hdd.drive import benchmark_drive
from servo.hdd.plant import plants
from servo.runtime.controller import Controller
from tests.helpers import SHARED

PACKAGE = SHARED / "data" / "nss-hdd-benchmark"
NUM = r"[-+]?\d*\.?\d+(?:[eE][-+]?\d+)?"


def _matrix(text: str) -> np.ndarray:
    rows = [r for r in re.split(r"[;\n]", text) if r.strip()]
    return np.array([[float(v) for v in re.findall(NUM, r)] for r in rows])


def followdemo() -> dict:
    """The benchmark's controller as its ``followdemo.m`` writes it: the notch
    state-space matrices at ``Tc = Ts/2`` by centre (Hz), the PID gains and ``g_adjust``."""
    text = (PACKAGE / "example1" / "followdemo.m").read_text(errors="replace")
    block = re.compile(r"a\s*=\s*\[(.*?)\];\s*b\s*=\s*\[(.*?)\];\s*c\s*=\s*\[(.*?)\];\s*d\s*=\s*(" + NUM + r");\s*"
                       r"sys_NF_(\d+)\s*=\s*ss\(a,\s*b,\s*c,\s*d,\s*Tc\)", re.S)  # fmt: skip
    notches = {int(m[5]): tuple(_matrix(m[i]) for i in range(1, 4)) + (float(m[4]),) for m in block.finditer(text)}
    pid = [float(v) for v in re.findall(NUM, re.search(r"coef_PID\s*=\s*\[(.*?)\]", text)[1])]
    g = float(re.search(r"g_adjust\s*=\s*(" + NUM + ")", text)[1])
    return dict(notches=notches, pid=pid, g=g)


def nss_config(**over) -> Config:
    return Config().replace(**benchmark_drive(2), controller={"kind": "nss", **over})


def nss_design(cfg: Config):
    ctl = Controller(cfg)
    return ctl.kind.designed(cfg.controller.section, cfg)


def test_the_kinds_defaults_are_the_benchmarks_notches():
    s = NSSSection()
    assert list(zip(s.notch_hz, s.notch_depth_db, s.notch_width)) == [tuple(n) for n in NSS_NOTCHES]


def test_the_nss_kind_rebuilds_the_benchmarks_controller_from_followdemo():
    ref = followdemo()
    assert sorted(ref["notches"]) == [4100, 5000, 8200, 12300] and ref["pid"] == [2.0, 0.05, 70.0]
    Ts = benchmark(2).Ts
    d = nss_design(nss_config())
    assert d.pes_every == 2 and d.fs == pytest.approx(2 / Ts)
    f = np.linspace(100.0, 1 / Ts - 100.0, 800)
    # the notches, in the package's order of centres, against the matrices (4 digits)
    assert d.fast_sos.shape[0] == 4
    for row, f0 in zip(d.fast_sos, sorted(ref["notches"])):
        A, B, C, D = ref["notches"][f0]
        num, den = signal.ss2tf(A, B, C, [[D]])
        _, h_ref = signal.freqz(num[0], den, worN=f, fs=2 / Ts)
        err = np.max(np.abs(sections.response(row, f, 2 / Ts) - h_ref))
        assert err < 5e-3, (f0, err)
    # the PID: sys_C = tf(P[1 -1 0] + I[0 1 0] + D[1 -2 1], [1 -1 0], Ts) / g_adjust, PES in tracks
    P, I, D = ref["pid"]
    num = (P * np.array([1, -1, 0]) + I * np.array([0, 1, 0]) + D * np.array([1, -2, 1])) / ref["g"]
    _, c_ref = signal.freqz(num, [1, -1, 0], worN=f[:200], fs=1 / Ts)
    assert np.allclose(d.slow_response(f[:200]) * 2.54e-7, c_ref, rtol=1e-12)


def test_the_nss_kind_is_stable_on_every_perturbed_plant():
    b = benchmark(2)
    d = nss_design(nss_config())
    radii = {name: np.abs(control.feedback(loop.open_loop(d, p, b.Td), 1).poles()).max() for name, p in plants(b)}
    assert len(radii) == 54
    worst = max(radii, key=radii.get)
    assert radii[worst] < 1.0, (worst, radii[worst])


def test_the_written_in_runout_is_the_packages():
    seq = written_in_rro(PACKAGE)
    assert seq.shape == (220,) and np.ptp(seq) == pytest.approx(0.0924, abs=5e-4)  # tracks, 9.2 % p-p
    n = 220 * 2 * 5
    with_seq, alone = generate(n, 2, seed=4, package=PACKAGE), generate(n, 2, seed=4)
    Tp = benchmark(2).Tp
    assert with_seq.written_in and not alone.written_in
    assert np.allclose(with_seq.rro - alone.rro, np.tile(seq, 5) * Tp, rtol=0, atol=1e-20)
    assert np.array_equal(with_seq.flutter, alone.flutter) and np.array_equal(with_seq.force, alone.force)


def test_a_package_without_the_runout_is_one_clear_error(tmp_path):
    with pytest.raises(ValueError, match="RROSequence.mat: not found"):
        generate(440, 2, package=tmp_path)
    (tmp_path / "RROSequence.mat").write_text("not a mat file")
    with pytest.raises(ValueError, match="RROSequence.mat"):
        written_in_rro(tmp_path)


def test_the_scenario_reads_the_users_package(tmp_path):
    from servo.scenarios import scenario_inputs

    over = benchmark_drive(2)
    over["run"]["duration_s"] = 0.01
    cfg = Config().replace(**over, controller={"kind": "nss"}, scenario={"kind": "hdd_benchmark"})
    alone = scenario_inputs(cfg).dist
    cfg_pkg = cfg.replace(scenario={"hdd_package": str(PACKAGE)})
    dist = scenario_inputs(cfg_pkg).dist
    assert dist.written_in and np.ptp(dist.rro_revolution - alone.rro_revolution) > 0.09 * 2.54e-7
    with pytest.raises(ConfigError, match="hdd_package|RROSequence"):
        scenario_inputs(cfg.replace(scenario={"hdd_package": str(tmp_path)}))
    toml = tmp_path / "c.toml"
    toml.write_text('[scenario]\nkind = "hdd_benchmark"\nhdd_package = 3\n')
    with pytest.raises(ConfigError, match="hdd_package must be a string"):
        load_config(toml)

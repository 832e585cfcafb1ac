"""The reference firmware (``firmware/``, C99), built for this machine.

* unit tests through ctypes (``firmware/hal_test.c``: bytes in and out through buffers,
  a clock the test sets): COBS and CRC-32 against the Python framing, the simulated
  drive against the Numba plant kernels bit for bit, and the session state machine case
  by case (zero current in every state, CONFIG limits, watchdog and ready timeout,
  corrupt, out-of-sequence and bad frames, a second host), and byte for byte against the
  Python board (``hil/board.py``) on the same host bytes;
* the host build (a process on a pseudo-terminal) driven by ``servo run --port``: logs
  equal to the simulated drive's, bit for bit, for every controller kind; the link faults
  the emulator is tested with leave it at zero current.

Builds are cached in one temporary directory per test session (a second or two each).
"""
import ctypes
import math
import re
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hil import protocol as P
from hil.board import Board
from hil.firmware import (ROOT, build_host, build_mps2, build_test_library, comparable, find_cc, read_line, serve_host,
                          serve_qemu)
from hil.framing import FrameDecoder, encode_frame
from hil.serialdriver import SerialDriver
from kernels.compose import LOG_COLUMNS
from kernels.plant import plant_measure, plant_step
from servo.config import Config, to_toml
from servo.errors import DriverError
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.loop import run_closed_loop
from servo.scenarios import scenario_inputs
from servo.runtime.simdriver import SimDriver
from servo.runtime.simplant import build_plant
from tests.test_board import LIMITS

pytestmark = pytest.mark.skipif(find_cc() is None, reason="no C compiler")  # CI has one: never skipped there

MS = 1000  # the firmware's clock is in us
RATE = 50_000.0
#: two steps and the disturbance force from 8 ms on: every bit-equal run below has it
CFG = comparable(Config().replace(run={"duration_s": 0.02},
                                  scenario={"step_times": [0.005, 0.012], "step_positions": [2e-6, 0.0],
                                            "disturbance_start": 0.008, "disturbance_hz": 400.0}))  # fmt: skip
#: a drive with every effect the plant models, for the kernel vectors
FULL = comparable(Config().replace(
    drive={"input_delay_s": 1.3 / RATE, "cogging": 2e-3, "alpha": 0.7, "fc_asymmetry": 0.1, "b_asymmetry": 0.05, "kf_linear": 0.05, "kf_quadratic": -0.1,
           "sensor_cutoff_hz": 3000.0, "Fs": 0.004, "Fc": 0.003,
           "dead_zone": 1e-3, "k3": 1e3, "backlash_half_gap": 2e-6}))  # fmt: skip
IDLE, HELLO, READY, ACTIVE, FAULTED = range(5)


@pytest.fixture(scope="session")
def fw_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("firmware")


def _lib(cfg, fw_dir):
    lib = ctypes.CDLL(str(build_test_library(cfg, fw_dir)))
    u8p, dp = ctypes.POINTER(ctypes.c_uint8), ctypes.POINTER(ctypes.c_double)
    lib.cobs_encode.argtypes = [ctypes.c_char_p, ctypes.c_size_t, u8p]
    lib.cobs_encode.restype = ctypes.c_size_t
    lib.cobs_decode.argtypes = [ctypes.c_char_p, ctypes.c_size_t, u8p]
    lib.cobs_decode.restype = ctypes.c_long
    lib.crc32_bytes.argtypes = [ctypes.c_char_p, ctypes.c_size_t]
    lib.crc32_bytes.restype = ctypes.c_uint32
    lib.fwt_feed.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint32]
    lib.fwt_poll.argtypes = lib.fwt_tick.argtypes = [ctypes.c_uint32]
    lib.fwt_take.argtypes = [u8p, ctypes.c_size_t]
    lib.fwt_take.restype = ctypes.c_size_t
    lib.fwt_applied.restype = ctypes.c_double
    lib.fwt_stat.restype = lib.fwt_refused.restype = ctypes.c_uint32
    lib.fwt_plant_run.argtypes = [ctypes.c_int, dp, dp, dp]
    return lib


@pytest.fixture(scope="session")
def lib(fw_dir):
    return _lib(CFG, fw_dir)


# ------------------------------------------------------------------- framing, kernels


def _c_encode(lib, data: bytes) -> bytes:
    buf = (ctypes.c_uint8 * (len(data) + len(data) // 254 + 2))()
    return bytes(buf[: lib.cobs_encode(data, len(data), buf)])


def test_cobs_and_crc_are_the_python_framings(lib):
    rng = np.random.default_rng(5)
    bodies = [b"", b"\x00", b"\x00" * 300, bytes(range(1, 256)) * 3, b"123456789"]
    bodies += [rng.integers(0, 4, rng.integers(1, 1100)).astype(np.uint8).tobytes() for _ in range(200)]
    assert lib.crc32_bytes(b"123456789", 9) == 0xCBF43926
    for body in bodies:
        framed = body + zlib.crc32(body).to_bytes(4, "little")
        assert lib.crc32_bytes(body, len(body)) == zlib.crc32(body)
        enc = _c_encode(lib, framed)
        if len(body) >= 1:
            assert enc + b"\x00" == encode_frame(body)  # the Python sender's bytes exactly
        out = (ctypes.c_uint8 * len(enc))()
        assert bytes(out[: lib.cobs_decode(enc, len(enc), out)]) == framed
    for bad in (b"\x05\x01", b"\x02\x00", b"\x00"):  # a code past the end, a zero inside
        out = (ctypes.c_uint8 * 8)()
        assert lib.cobs_decode(bad, len(bad), out) == -1


def test_the_simulated_drive_is_the_numba_plant_bit_for_bit(fw_dir):
    """``firmware/plant.c`` against ``kernels/plant.py`` on the same commands and forces,
    with every effect on: input delay with a fractional part, flexible modes, cogging,
    force-constant variation, Stribeck friction, Dahl hysteresis, the backlash, the sensor
    low-pass, quantiser, an input dead zone, a cubic spring and hard stops (the commands
    drive the arm into them)."""
    lib = _lib(FULL, fw_dir)
    n = 4000
    rng = np.random.default_rng(11)
    u = np.concatenate([0.02 * np.sin(np.arange(n // 2) / 40.0), 0.9 * np.sign(rng.standard_normal(n - n // 2))])
    d = 1e-3 * rng.standard_normal(n)
    got = np.empty(2 * n)
    dp = ctypes.POINTER(ctypes.c_double)
    lib.fwt_plant_run(n, u.ctypes.data_as(dp), d.ctypes.data_as(dp), got.ctypes.data_as(dp))
    p = build_plant(FULL.drive, FULL.dt)
    want = np.empty(2 * n)
    for k in range(n):
        want[2 * k : 2 * k + 2] = plant_measure(p.state, p.params, p.q, p.gain, 0.0, 0.0)
        plant_step(p.state, p.params, p.q, p.mab, p.ubuf, u[k], d[k])
    assert np.ptp(want[0::2]) > 1e-3  # it went from stop to stop
    assert np.array_equal(got, want)


def test_the_disturbance_is_the_steps_scenarios_bit_for_bit(lib):
    """The simulated drive's disturbance force: the same bits as the scenario's, sign of
    zero included, before and after its start."""
    n = int(CFG.n_ticks)
    got = np.empty(n)
    lib.fwt_disturbance.argtypes = [ctypes.c_int, ctypes.POINTER(ctypes.c_double)]
    lib.fwt_disturbance(n, got.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
    want = scenario_inputs(CFG).disturbance(np.arange(n))
    assert np.array_equal(got.view(np.int64), want.view(np.int64))
    assert np.count_nonzero(want) > n // 2 and np.all(want[: int(0.008 * RATE)] == 0.0)


def _noise(lib, seed, n):
    out = np.empty(2 * n)
    lib.fwt_noise.argtypes = [ctypes.c_uint64, ctypes.c_int, ctypes.POINTER(ctypes.c_double)]
    lib.fwt_noise(seed, n, out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
    return out


def test_the_sensor_noise_draws_are_independent_standard_normals(lib):
    """firmware/noise.c: 400 000 draws (200 000 ticks' pairs) have mean 0, variance 1, the
    normal's kurtosis and tails, pass Kolmogorov-Smirnov against the normal, and are
    uncorrelated from tick to tick and between a tick's position and velocity draws; each
    bound is 5 standard errors.  A seed gives its draws again; another seed others."""
    from scipy import stats

    n = 200_000
    z = _noise(lib, 1, n)
    N = z.size
    assert abs(z.mean()) < 5 / math.sqrt(N)
    assert abs(z.var() - 1.0) < 5 * math.sqrt(2.0 / N)
    assert abs(stats.kurtosis(z)) < 5 * math.sqrt(24.0 / N)
    tail = np.mean(np.abs(z) > 3.0)
    p3 = 2 * stats.norm.sf(3.0)
    assert abs(tail - p3) < 5 * math.sqrt(p3 * (1 - p3) / N)
    assert stats.kstest(z, "norm").pvalue > 1e-4
    pairs = z.reshape(n, 2)
    assert abs(np.corrcoef(z[:-1], z[1:])[0, 1]) < 5 / math.sqrt(N)
    assert abs(np.corrcoef(pairs[:-1, 0], pairs[1:, 0])[0, 1]) < 5 / math.sqrt(n)
    assert abs(np.corrcoef(pairs[:, 0], pairs[:, 1])[0, 1]) < 5 / math.sqrt(n)
    assert np.array_equal(_noise(lib, 1, 1000), z[:2000]) and not np.array_equal(_noise(lib, 2, 1000), z[:2000])


def test_the_noisy_drive_is_the_python_drive_in_distribution(fw_dir):
    """With the sensor noise on, the firmware's drive held at rest samples what the
    Python simulated drive samples, in distribution: position and velocity, two-sample
    Kolmogorov-Smirnov over 20 000 ticks, and standard deviations within 5 % (the
    standard error of each is 0.5 %)."""
    from scipy import stats

    cfg = CFG.replace(drive={"position_noise": 3e-9, "velocity_noise": 1e-6},
                      scenario={"disturbance_amplitude": 0.0}, run={"duration_s": 0.4})  # fmt: skip
    noisy = _lib(cfg, fw_dir)
    u_hold = build_plant(cfg.drive, cfg.dt).u_hold
    n = cfg.n_ticks
    host = _fresh(noisy)
    host.configure(watchdog_ms=50)
    host.send(P.start)
    for k in range(n):
        host.send(lambda s: P.commands(s, k, (u_hold,)))
    fw = np.array([m.values[:2] for m in host.recv() if isinstance(m, P.Samples)])[:n]
    sim = SimDriver(cfg)
    sim.configure()
    sim.activate()
    py = np.empty((n, 2))
    for k in range(n):
        py[k] = sim.read()
        sim.write(u_hold)
    for j in (0, 1):
        assert stats.ks_2samp(fw[:, j], py[:, j]).pvalue > 1e-4, j
        assert abs(np.std(fw[:, j]) / np.std(py[:, j]) - 1.0) < 0.05, j
    assert np.std(py[:, 1]) > 0.5e-6 and not np.array_equal(fw, py)


def test_one_firmware_binary_gives_each_run_the_seed_of_its_config(fw_dir, tmp_path):
    """The seed travels in CONFIG (protocol version 3), not in the build: configs that
    differ in run.seed build the same binary; against one running firmware, two runs with
    seed 7 record the same noisy log, bit for bit, and a run with seed 8 another."""
    cfg = CFG.replace(drive={"position_noise": 3e-9, "velocity_noise": 1e-6}, run={"duration_s": 0.004},
                      link={"watchdog_s": 2.0, "timeout_s": 2.0})  # fmt: skip
    exe = build_host(cfg.replace(run={"seed": 7}), fw_dir)
    assert build_host(cfg.replace(run={"seed": 8}), fw_dir) == exe
    logs = {}
    with serve_host(exe) as (proc, url):
        for name, seed in (("a", 7), ("b", 7), ("c", 8)):
            run = cfg.replace(run={"seed": seed})
            logs[name] = run_log(run, SerialDriver(run, url), tmp_path, name)
    x, u = LOG_COLUMNS.index("x"), LOG_COLUMNS.index("u")
    assert np.array_equal(logs["a"], logs["b"], equal_nan=True)
    assert not np.array_equal(logs["a"][:, x], logs["c"][:, x])  # other noise, measured
    assert not np.array_equal(logs["a"][:, u], logs["c"][:, u])  # and the loop answered it
    assert np.std(np.diff(logs["a"][:, LOG_COLUMNS.index("v")])) > 1e-7  # the noise is on


def test_the_controller_records_header_is_the_dtypes():
    from bench.cref import records_file

    assert (ROOT / "records.h").read_text() == records_file()  # regenerate it with python -m bench.cref


@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
@pytest.mark.parametrize("terms", ["plain", "every_term"])
def test_every_controller_kind_is_the_numba_kernels_bit_for_bit(lib, kind, terms):
    """``firmware/controller.c`` against the composed Numba kernels of each kind, on the
    same inputs, from the same bumpless start: the same commands and the same records
    after 3000 samples."""
    cfg = CFG.replace(controller={"kind": kind})
    if terms == "every_term":
        cfg = cfg.replace(compensator={"kf_linear": 0.05, "kf_quadratic": -0.1, "coulomb_extra": 1e-3, "b_asymmetry": 0.1,
                                       "periodic_amplitudes": [1e-4, 5e-5], "periodic_phases": [0.3, 1.0],
                                       "authority": 0.5, "k3": 1e4, "dead_zone": 2e-4})  # fmt: skip
    py, c = Controller(cfg), Controller(cfg)
    py.start(1e-7, 0.0, 2e-3)
    c.buf[:] = py.buf
    tick = lib.fw_pi_tick if kind == "pi" else lib.fw_track_tick
    tick.restype = ctypes.c_double
    tick.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_double] * 4
    ptrs = [a.ctypes.data for a in c.records()]
    rng = np.random.default_rng(3)
    x = np.cumsum(2e-8 * rng.standard_normal(3000))
    v = np.where(rng.random(3000) < 0.2, np.nan, 1e-3 * rng.standard_normal(3000))
    r = np.where(np.arange(3000) > 1000, 1e-6, 0.0)
    u_exc = 1e-4 * rng.standard_normal(3000)
    for k in range(3000):
        want = py.tick(x[k], v[k], r[k], u_exc[k])
        got = tick(*ptrs, x[k], v[k], r[k], u_exc[k])
        assert got == want or (math.isnan(got) and math.isnan(want)), (k, got, want)
    assert py.buf.tobytes() == c.buf.tobytes()


# ------------------------------------------------------------------- the state machine


class Host:
    """The host's bytes by hand, into the C board (``lib``) or a Python :class:`Board`."""

    def __init__(self, lib=None, board=None):
        self.lib, self.board, self.seq, self.dec = lib, board, 0, FrameDecoder()

    def raw(self, data: bytes, now=0):
        if self.lib is not None:
            self.lib.fwt_feed(data, len(data), now)
        else:
            self.board.feed(data, now * 1000)

    def send(self, make, now=0):
        self.raw(encode_frame(make(self.seq)), now)
        self.seq += 1

    def out(self) -> bytes:
        if self.lib is None:
            data = bytes(self.board.out)
            self.board.out.clear()
            return data
        buf = (ctypes.c_uint8 * (1 << 16))()
        return bytes(buf[: self.lib.fwt_take(buf, len(buf))])

    def recv(self):
        return [m for _, _, m in (P.parse(b) for b in self.dec.feed(self.out()))]

    def configure(self, b=1, d=0, watchdog_ms=5, late=0, ready_ms=500, now=0, rate=RATE):
        self.send(lambda s: P.hello(s, 7), now)
        self.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, b, d, watchdog_ms * 1000, late, rate, ready_ms)), now)
        return self.recv()


def _fresh(lib, lockstep=1):
    lib.fwt_init(lockstep)
    return Host(lib)


def test_zero_current_at_power_up_and_in_every_state_but_ready_and_active(lib):
    host = _fresh(lib)
    assert lib.fwt_state() == IDLE and lib.fwt_applied() == 0.0
    host.send(lambda s: P.hello(s, 1))
    info = host.recv()[0]
    assert lib.fwt_state() == HELLO and lib.fwt_applied() == 0.0
    assert info.nonce == 1 and info.v_min == info.v_max == P.VERSION and info.sample_rate_hz == RATE
    assert info.caps == P.CAP_VELOCITY | P.CAP_CURRENT | P.CAP_LOCKSTEP | P.CAP_LOOP and info.max_batch == 32
    host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 5000, 0, RATE)))
    (ready,) = host.recv()
    assert lib.fwt_state() == READY and ready.i == lib.fwt_applied() != 0.0  # the holding current
    host.send(P.start)
    assert lib.fwt_state() == ACTIVE and isinstance(host.recv()[0], P.Samples)
    host.send(lambda s: P.commands(s, 0, (0.05,)))
    assert lib.fwt_applied() == 0.05
    host.send(P.stop)
    assert lib.fwt_state() == HELLO and lib.fwt_applied() == 0.0 and isinstance(host.recv()[-1], P.Stats)


#: the Python board's cases (tests/test_board.py), the late limits at this drive's 50 kHz
FW_LIMITS = [c for c in LIMITS if "late_limit" not in c[0]] + [({"late_limit": 251, "watchdog_us": 5000}, "late limit 251"),
                                                                ({"late_limit": 65535, "watchdog_us": 1000}, "late limit")]


@pytest.mark.parametrize("change,needle", FW_LIMITS, ids=[next(iter(c)) + str(i) for i, (c, _) in enumerate(FW_LIMITS)])
def test_a_config_beyond_the_documented_limits_is_refused(lib, change, needle):
    host = _fresh(lib, lockstep=0)
    host.send(lambda s: P.hello(s, 1))
    msg = P.ConfigMsg(P.VERSION, 1, 1, 5000, 0, RATE)._replace(**change)
    host.send(lambda s: P.config(s, msg))
    _, fault, stats = host.recv()
    assert fault.code == P.FAULT_CONFIG and lib.fwt_state() == FAULTED and lib.fwt_applied() == 0.0
    field = next(iter(change)).replace("_us", "").replace("_ms", "").replace("_", " ")
    assert field in fault.text, fault.text  # it says which
    assert stats.counters["faults"] == 1


_u = lambda n: st.integers(0, 2**n - 1)  # noqa: E731
_around = lambda n, limit: _u(n) | st.integers(0, 2 * limit) | st.integers(limit - 2, limit + 2)  # noqa: E731
_CONFIGS = st.builds(P.ConfigMsg, st.sampled_from([3, 3, 3, 2, 4]), _around(8, 32), st.integers(0, 1100),
                     _around(32, P.MAX_WATCHDOG_US), _around(16, 1000), st.sampled_from([RATE, RATE, 40_000.0, math.nan]),
                     _u(16) | st.integers(P.MAX_READY_TIMEOUT_MS - 2, P.MAX_READY_TIMEOUT_MS + 2),
                     _u(64) | st.integers(P.MAX_SEED - 2, P.MAX_SEED + 2))  # fmt: skip


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(msg=_CONFIGS, lockstep=st.booleans())
def test_any_config_gets_the_python_boards_decision(lib, msg, lockstep):
    """Hostile CONFIGs: the C board accepts exactly those the Python board accepts, and
    holds current only then."""
    decisions = []
    for host in (Host(board=Board(CFG, lockstep=lockstep)), _fresh(lib, int(lockstep))):
        host.send(lambda s: P.hello(s, 1))
        host.send(lambda s: P.config(s, msg))
        kinds = [type(m).__name__ for m in host.recv()]
        decisions.append(kinds)
    assert decisions[0] == decisions[1], (msg, decisions)
    assert (lib.fwt_state() == READY) == ("Ready" in decisions[1])
    assert lib.fwt_applied() == 0.0 or lib.fwt_state() == READY


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(noise=st.lists(st.binary(max_size=80), max_size=12))
def test_noise_into_a_running_board_ends_at_zero_current_or_changes_nothing(lib, noise):
    host = _running(lib)
    for chunk in noise:
        host.raw(chunk)
    state = lib.fwt_state()
    assert state in (ACTIVE, FAULTED)
    assert (lib.fwt_applied() == 0.0) == (state == FAULTED)


def test_the_ready_timeout_and_the_watchdog_end_in_zero_current(lib):
    host = _fresh(lib)
    host.configure(watchdog_ms=5, ready_ms=300)
    lib.fwt_poll(300 * MS)
    assert lib.fwt_state() == READY and lib.fwt_applied() != 0.0
    lib.fwt_poll(300 * MS + 1)
    fault, stats = host.recv()
    assert fault.code == P.FAULT_WATCHDOG and "after READY" in fault.text and lib.fwt_applied() == 0.0
    host = _fresh(lib)
    host.configure(watchdog_ms=5, ready_ms=300)
    host.send(P.start, now=100 * MS)
    host.send(lambda s: P.commands(s, 0, (0.01,)), now=101 * MS)
    lib.fwt_poll(106 * MS)
    assert lib.fwt_state() == ACTIVE and lib.fwt_applied() == 0.01
    lib.fwt_poll(106 * MS + 1)  # a silent host
    fault = [m for m in host.recv() if isinstance(m, P.Fault)][0]
    assert fault.code == P.FAULT_WATCHDOG and "no command for" in fault.text
    assert lib.fwt_state() == FAULTED and lib.fwt_applied() == 0.0 and lib.fwt_stat(11) == 1


def _running(lib):
    host = _fresh(lib)
    host.configure(watchdog_ms=50)
    host.send(P.start)
    host.send(lambda s: P.commands(s, 0, (0.02,)))
    assert lib.fwt_state() == ACTIVE and lib.fwt_applied() == 0.02
    host.recv()
    return host


@pytest.mark.parametrize("how,code", [
    ("corrupt", P.FAULT_CORRUPT), ("garbage", P.FAULT_CORRUPT), ("oversize", P.FAULT_CORRUPT),
    ("repeat", P.FAULT_SEQUENCE), ("skip", P.FAULT_SEQUENCE), ("nan", P.FAULT_COMMAND), ("inf", P.FAULT_COMMAND),
    ("future", P.FAULT_COMMAND), ("wrong_tick", P.FAULT_COMMAND), ("malformed", P.FAULT_PROTOCOL),
    ("old_version", P.FAULT_PROTOCOL), ("config_while_active", P.FAULT_PROTOCOL),
])  # fmt: skip
def test_every_bad_frame_while_active_is_a_fault_at_zero_current(lib, how, code):
    host = _running(lib)
    if how == "corrupt":
        frame = bytearray(encode_frame(P.commands(host.seq, 1, (0.02,))))
        frame[5] ^= 0x5A
        host.raw(bytes(frame))
    elif how == "garbage":
        host.raw(b"\x03\xff\xff\x00")
    elif how == "oversize":
        host.raw(b"\x01" * 1100)
    elif how == "repeat":
        host.seq -= 1
        host.send(lambda s: P.commands(s, 1, (0.02,)))
    elif how == "skip":
        host.seq += 1
        host.send(lambda s: P.commands(s, 1, (0.02,)))
    elif how in ("nan", "inf"):
        host.send(lambda s: P.commands(s, 1, (float(how),)))
    elif how == "future":
        host.send(lambda s: P.commands(s, 1, (0.0, 0.0, 0.0)))  # samples 2, 3 not sent yet
    elif how == "wrong_tick":
        host.send(lambda s: P.commands(s, 5, (0.0,)))
    elif how == "malformed":
        host.send(lambda s: P.commands(s, 1, (0.0,))[:-1])
    elif how == "old_version":
        host.send(lambda s: b"\x01" + P.commands(s, 1, (0.0,))[1:])
    elif how == "config_while_active":
        host.send(lambda s: P.config(s, P.ConfigMsg(P.VERSION, 1, 0, 5000, 0, RATE)))
    if how == "oversize":
        host.raw(b"\x00")
    faults = [m for m in host.recv() if isinstance(m, P.Fault)]
    assert [f.code for f in faults] == [code], faults
    assert lib.fwt_state() == FAULTED and lib.fwt_applied() == 0.0
    host.send(lambda s: P.commands(s, 1, (0.5,)))  # nothing but HELLO (or STOP) is heard now
    assert lib.fwt_applied() == 0.0 and lib.fwt_state() == FAULTED


def test_a_second_hosts_hello_is_refused_while_a_session_runs(lib):
    host = _running(lib)
    other = Host(lib)
    other.send(lambda s: P.hello(s, 9))
    assert other.recv() == [] and lib.fwt_refused() == 1 and lib.fwt_state() == ACTIVE
    host.send(lambda s: P.commands(s, 1, (0.03,)))
    assert lib.fwt_applied() == 0.03  # the first host's session is undisturbed
    host.send(P.stop)
    other.send(lambda s: P.hello(s, 9))
    assert lib.fwt_state() == HELLO and [m.nonce for m in other.recv() if isinstance(m, P.Info)] == [9]


def test_real_time_holds_late_commands_then_faults_on_missed_deadlines(lib):
    host = _fresh(lib, lockstep=0)
    host.configure(d=1, late=2, watchdog_ms=50)
    host.send(P.start)
    lib.fwt_tick(0)  # tick 0: the holding current
    host.send(lambda s: P.commands(s, 0, (0.02,)))
    lib.fwt_tick(0)  # tick 1: u_0
    assert lib.fwt_applied() == 0.02
    lib.fwt_tick(0)
    lib.fwt_tick(0)  # ticks 2, 3 held
    assert lib.fwt_stat(9) == 2 and lib.fwt_state() == ACTIVE
    lib.fwt_tick(0)  # the third in a row > late limit 2
    assert lib.fwt_state() == FAULTED and lib.fwt_applied() == 0.0
    assert [m.code for m in host.recv() if isinstance(m, P.Fault)] == [P.FAULT_DEADLINE]


@pytest.mark.parametrize("d,b", [(0, 1), (3, 2), (8, 8)])
def test_byte_for_byte_the_python_boards_answers(lib, d, b):
    """The same host bytes into the C board and the Python board (same drive, no noise):
    every frame from READY on is the same, byte for byte (INFO differs by its name)."""
    py, c = Host(board=Board(CFG)), _fresh(lib)
    rng = np.random.default_rng(d)
    outs = {}
    for host in (py, c):
        host.configure(b=b, d=d, watchdog_ms=50)
        host.send(P.start)
        for m in range(40):
            host.send(lambda s: P.commands(s, m * b, tuple(2e-3 + 1e-3 * rng.standard_normal(b))))
        host.send(P.stop)
        outs[host is c] = host.out()
        rng = np.random.default_rng(d)
    assert outs[True] == outs[False] and len(outs[True]) > 40 * b * 24


# ------------------------------------------------------------------- the host build


@pytest.fixture(scope="module")
def host_build(fw_dir):
    return build_host(CFG, fw_dir)


def run_log(cfg, driver, tmp_path, name):
    controller = Controller(cfg)
    with driver, RunLog(tmp_path, name, controller.log_columns) as log:
        run_closed_loop(cfg, driver, controller, scenario_inputs(cfg), log)
    return log.recorded().copy()


@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_every_controller_kind_through_the_firmware_is_the_simulated_drives_run(host_build, kind, tmp_path):
    cfg = CFG.replace(controller={"kind": kind}, link={"watchdog_s": 2.0, "timeout_s": 2.0, "command_latency_ticks": 1,
                                                       "batch": 2})  # fmt: skip
    with serve_host(host_build) as (proc, url):
        hil = run_log(cfg, SerialDriver(cfg, url), tmp_path, "fw")
    sim = run_log(cfg, SimDriver(cfg, scenario_inputs(cfg)), tmp_path, "sim")
    assert hil.shape == sim.shape and hil.shape[0] == cfg.n_ticks
    assert np.array_equal(hil, sim, equal_nan=True)  # every column, every bit
    assert np.ptp(sim[:, LOG_COLUMNS.index("x")]) > 1e-6  # the steps happened


def servo_run_both(cfg, url, tmp_path, *options):
    """``servo run --port URL`` and ``servo run`` (the simulated drive) of ``cfg`` with
    ``options``; returns the two output folders."""
    from servo.cli import main

    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text(to_toml(cfg))
    fw, sim = tmp_path / "fw", tmp_path / "sim"
    assert main(["run", "--config", str(cfg_file), "--port", url, "--out", str(fw), "--quiet", *options]) == 0
    assert main(["run", "--config", str(cfg_file), "--out", str(sim), "--quiet", *options]) == 0
    return fw, sim


def assert_same_logs(fw, sim, kind, atol=None):
    """The compensated and uncompensated logs of two ``servo run`` folders, every column:
    bit for bit (``atol`` None), or each continuous column within ``atol`` times its
    largest magnitude and every other column (tick, time, reference, the quantised
    position, regime, excitation) bit for bit."""
    continuous = {"v", "u", "u_n", "u_c", "h_hat", "e", "pes"}
    for label in ("compensated", "uncompensated"):
        a, b = np.load(fw / f"log_{label}.npz"), np.load(sim / f"log_{label}.npz")
        cols = list(LOG_COLUMNS) + ([] if kind == "pi" else ["pes"])
        assert set(cols) <= set(a.files) and set(cols) <= set(b.files)
        for col in cols:
            if atol is None or col not in continuous:
                assert np.array_equal(a[col], b[col], equal_nan=True), (label, col)
            else:
                scale = np.nanmax(np.abs(b[col]))
                assert np.allclose(a[col], b[col], rtol=0.0, atol=atol * scale, equal_nan=True), (label, col)
        assert np.ptp(b["x"]) > 1e-6


@pytest.mark.slow  # two runs of servo run in-process per kind, 10-15 s on a loaded machine
@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_servo_run_port_against_the_firmware_gives_the_simulators_logs(host_build, kind, tmp_path):
    cfg = CFG.replace(controller={"kind": kind}, link={"watchdog_s": 2.0, "timeout_s": 2.0})
    with serve_host(host_build) as (proc, url):
        fw, sim = servo_run_both(cfg, url, tmp_path)
        lines = [read_line(proc, 2.0) for _ in range(4)]
    assert all("drive at zero current" in line for line in lines[1::2]), lines
    assert_same_logs(fw, sim, kind)


@pytest.mark.slow  # two runs of servo run in-process per kind
@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_servo_run_loop_on_board_against_the_firmware_gives_the_simulators_logs(host_build, kind, tmp_path):
    """``servo run --port URL --loop-on-board``: the board runs the kind, the host records;
    its logs equal ``servo run --loop-on-board`` on the simulated drive (the loop with no
    link latency), bit for bit, compensated and not, the disturbance on."""
    cfg = CFG.replace(controller={"kind": kind}, link={"watchdog_s": 2.0, "timeout_s": 2.0, "batch": 4,
                                                       "command_latency_ticks": 3})  # fmt: skip
    with serve_host(host_build) as (proc, url):
        fw, sim = servo_run_both(cfg, url, tmp_path, "--loop-on-board")
    assert_same_logs(fw, sim, kind)
    summary = (fw / "summary.json").read_text()
    assert "the loop on the board" in summary


@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_the_loop_on_the_board_logs_the_simulated_drives_run(host_build, kind, tmp_path):
    """The controller kind runs on the board (its records sent after READY, the reference
    streamed ahead, log rows streamed back): the log equals the simulated drive's run of
    the same config with no link latency, bit for bit (same operations, same order)."""
    from hil.onboard import run_on_board

    cfg = CFG.replace(controller={"kind": kind}, link={"watchdog_s": 2.0, "timeout_s": 2.0, "batch": 4,
                                                       "command_latency_ticks": 3, "loop": "board"})  # fmt: skip
    inputs = scenario_inputs(cfg)
    ticks = np.arange(cfg.n_ticks)
    controller = Controller(cfg)
    with serve_host(host_build) as (proc, url), RunLog(tmp_path, "board", controller.log_columns) as log:
        run_on_board(cfg, url, controller, inputs.reference(ticks), inputs.excitation(ticks), log)
    board = log.recorded().copy()
    sim = run_log(cfg, SimDriver(cfg, scenario_inputs(cfg)), tmp_path, "sim")  # link.loop = board: no latency
    assert board.shape == sim.shape
    assert np.array_equal(board, sim, equal_nan=True)
    assert np.ptp(sim[:, LOG_COLUMNS.index("x")]) > 1e-6


@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_the_board_logs_every_nth_row_and_gives_the_simulated_drives_log_and_estimate(host_build, kind, tmp_path):
    """run.log_every = 5 and run.estimator_every = 10: the board sends the rows of every
    5th tick only (their greatest common divisor), 4 to a LOG frame, and the host records
    the simulated drive's log and tracking-error statistics bit for bit; a gain change
    after the last logged row is still acknowledged."""
    from hil.onboard import GainChange, OnBoardDriver, link_log_every

    cfg = CFG.replace(controller={"kind": kind}, run={"log_every": 5, "estimator_every": 10},
                      link={"watchdog_s": 2.0, "timeout_s": 2.0, "batch": 4, "command_latency_ticks": 3,
                            "loop": "board"})  # fmt: skip
    assert link_log_every(cfg) == 5 and link_log_every(cfg.replace(run={"log_every": 4})) == 2
    last = cfg.n_ticks - 2  # after tick 995, the last logged row
    gains = [GainChange(last, _kind_params(cfg, kind))]  # the same gains: the run is unchanged
    results = {}
    with serve_host(host_build) as (proc, url):
        drv = OnBoardDriver(cfg, url, gains)
        controller = Controller(cfg)
        with drv, RunLog(tmp_path, "board", controller.log_columns) as log:
            results["board"] = run_closed_loop(cfg, drv, controller, scenario_inputs(cfg), log)
        board = log.recorded().copy()
    assert drv.log_frames == cfg.n_ticks // 5 // 4 and drv.acknowledged == [last]
    controller = Controller(cfg)
    with SimDriver(cfg, scenario_inputs(cfg)) as sim_drv, RunLog(tmp_path, "sim", controller.log_columns) as log:
        results["sim"] = run_closed_loop(cfg, sim_drv, controller, scenario_inputs(cfg), log)
    sim = log.recorded().copy()
    assert board.shape == sim.shape == (cfg.n_ticks // 5, len(controller.log_columns))
    assert np.array_equal(board, sim, equal_nan=True)
    assert np.array_equal(results["board"].stats, results["sim"].stats)
    assert results["sim"].stats[1] == cfg.n_ticks // 10  # every 10th tick's error


def test_a_run_whose_logged_rows_do_not_fill_whole_frames_is_refused(host_build, tmp_path):
    from hil.onboard import OnBoardDriver

    cfg = CFG.replace(run={"log_every": 3, "estimator_every": 3}, link={"batch": 4, "command_latency_ticks": 3, "loop": "board"})
    with serve_host(host_build) as (proc, url):
        with pytest.raises(DriverError, match=r"334 rows \(one every 3 ticks of 1000\) are not a multiple of 4"):
            OnBoardDriver(cfg, url).configure()  # at the handshake: before a job writes anything
        _zero_current_line(proc)  # the session it opened is closed: the board at zero current


def _zero_current_line(proc, timeout=5.0) -> str:
    end = time.monotonic() + timeout
    seen = []
    while (line := read_line(proc, max(0.0, end - time.monotonic()))) is not None:
        seen.append(line)
        if "drive at zero current" in line:
            return line
    raise AssertionError(f"the firmware never said it is at zero current: {seen}")


FAULT_CFG = CFG.replace(run={"duration_s": 0.02}, link={"command_latency_ticks": 2, "timeout_s": 2.0, "watchdog_s": 2.0})
LINK_FAULTS = [  # (faulty:// option, link changes, what the host says, what the firmware says)
    ("corrupt_tx=104", {}, r"board fault, corrupt frame", "FAULT 3"),
    ("dup_tx=104", {}, r"board fault, sequence error .*a repeated frame", "FAULT 4"),
    ("silent_tx=104", {"watchdog_s": 0.2}, r"board fault, watchdog at tick \d+: no command for", "FAULT 1"),
    ("corrupt_rx=103", {}, r"corrupt frame from the board at tick 100", "stopped by the host after"),
]


ON_BOARD_FAULTS = [("corrupt_tx=8", {}, r"board fault, corrupt frame", "FAULT 3"),
                   ("dup_tx=8", {}, r"board fault, sequence error", "FAULT 4"),
                   ("silent_tx=8", {"watchdog_s": 0.2}, r"board fault, watchdog at tick \d+: no command for", "FAULT 1")]


@pytest.mark.parametrize("fault,link,host_says,fw_says", ON_BOARD_FAULTS, ids=[f[0] for f in ON_BOARD_FAULTS])
def test_a_link_fault_with_the_loop_on_the_board_leaves_it_at_zero_current(host_build, fault, link, host_says, fw_says,
                                                                            tmp_path):  # fmt: skip
    """The loop on the board under the same link faults: a corrupt, duplicated or missing
    host frame (REFS) is a fault at zero current, the rows before it on disk."""
    from hil.onboard import run_on_board

    cfg = FAULT_CFG.replace(controller={"kind": "track"}, link={"loop": "board", "batch": 2, **link})
    inputs, ticks = scenario_inputs(cfg), np.arange(cfg.n_ticks)
    controller = Controller(cfg)
    with serve_host(host_build) as (proc, url):
        with pytest.raises(DriverError, match=host_says):
            with RunLog(tmp_path, "log", controller.log_columns) as log:
                run_on_board(cfg, f"faulty://{url}?{fault}", controller, inputs.reference(ticks),
                             inputs.excitation(ticks), log)  # fmt: skip
        line = _zero_current_line(proc)
    assert fw_says in line, line
    rows = np.load(tmp_path / "log.npz")["tick"].shape[0]
    assert rows in (64, 96)  # HELLO, CONFIG, LOOP pieces, START, then REFS of 32 ticks: frame 8 is ticks 64..95


@pytest.mark.parametrize("fault,link,host_says,fw_says", LINK_FAULTS, ids=[f[0] for f in LINK_FAULTS])
def test_a_link_fault_leaves_the_firmware_at_zero_current(host_build, fault, link, host_says, fw_says, tmp_path):
    cfg = FAULT_CFG.replace(link=link)
    with serve_host(host_build) as (proc, url):
        drv = SerialDriver(cfg, f"faulty://{url}?{fault}")
        with pytest.raises(DriverError, match=host_says):
            run_log(cfg, drv, tmp_path, "log")
        line = _zero_current_line(proc)
    assert fw_says in line, line
    rows = np.load(tmp_path / "log.npz")["tick"].shape[0]
    assert 100 <= rows <= 105  # every tick before the fault is on disk


def test_a_host_too_slow_for_the_real_time_firmware_is_a_deadline_fault(fw_dir, tmp_path):
    """The host build paced on the clock (``--realtime``, 2 kHz): a host that stalls 30 ms
    misses its deadline; the board holds, then faults, at zero current."""
    cfg = comparable(Config().replace(run={"duration_s": 1.0, "sample_rate_hz": 2000.0},
                                      drive={"mode_hz": [], "mode_zeta": [], "mode_gain": []},
                                      link={"command_latency_ticks": 2, "watchdog_s": 1.0, "timeout_s": 0.5}))  # fmt: skip
    with serve_host(build_host(cfg, fw_dir), "--realtime") as (proc, url):
        drv = SerialDriver(cfg, f"faulty://{url}?pause_tx=400&pause_ms=30")  # the host stalls 30 ms at tick 396
        with pytest.raises(DriverError, match=r"board fault, deadline missed at tick \d+: the command of tick \d+ "
                           r"was not there at tick \d+: host too slow"):  # fmt: skip
            run_log(cfg, drv, tmp_path, "log")
        line = _zero_current_line(proc)
    assert "FAULT 2" in line and drv.board_stats["missed_deadlines"] >= 1 and drv.board_stats["faults"] == 1
    assert not drv.board_info.caps & P.CAP_LOCKSTEP


@pytest.mark.slow  # a second Python process: its imports alone take seconds
def test_a_second_host_is_refused_and_a_vanished_host_is_caught_by_the_watchdog(host_build, tmp_path):
    cfg = FAULT_CFG.replace(link={"watchdog_s": 0.2})
    with serve_host(host_build) as (proc, url):
        first = SerialDriver(cfg, url)
        first.configure()
        second = SerialDriver(cfg, url)
        with pytest.raises(DriverError, match="in use by another program"):
            second.configure()
        first.close()
        assert "stopped by the host before START" in _zero_current_line(proc)
        # a host process that dies mid-run without a word: the port vanishes under it
        script = (f"import sys; sys.path.insert(0, {os.getcwd()!r})\n"
                  "from hil.serialdriver import SerialDriver\nfrom servo.config import Config\n"
                  f"d = SerialDriver(Config().replace(link={{'watchdog_s': 0.2}}), {url!r})\n"
                  "d.configure(); d.activate()\nfor _ in range(50): d.read(); d.write(0.01)\n"
                  "import os; os.kill(os.getpid(), 9)\n")  # fmt: skip
        r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
        assert r.returncode == -signal.SIGKILL, r.stderr
        line = _zero_current_line(proc)
    assert "FAULT 1" in line and "no command for" in line


# ------------------------------------------------------------------- a real instruction set


needs_arm = pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None or shutil.which("qemu-system-arm") is None,
                               reason="no arm-none-eabi-gcc or qemu-system-arm (.ci/run installs them)")  # fmt: skip


@pytest.fixture(scope="module")
def mps2_build(fw_dir):
    return build_mps2(QEMU_CFG, fw_dir)


#: on the Cortex-M7, newlib's sin is not glibc's (both within an ulp of the true value,
#: not always the same one): the disturbance force differs by an ulp on some ticks, so
#: runs with it are equal to the simulated drive's to rounding (measured: 4e-19 in 8e-4,
#: 5e-16 relative), runs without it bit for bit
QEMU_CFG = CFG.replace(scenario={"disturbance_amplitude": 0.0},
                       link={"watchdog_s": 5.0, "timeout_s": 5.0, "ready_timeout_s": 10.0})  # fmt: skip
NEWLIB_SIN_TOLERANCE = 1e-12
"""Each continuous log column within this fraction of its largest magnitude."""


@pytest.mark.slow
@needs_arm
@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_servo_run_port_on_the_emulated_cortex_m7_gives_the_simulators_logs(mps2_build, kind, tmp_path):
    """The firmware cross-compiled for the MPS2 AN500 (Cortex-M7, double-precision FPU,
    newlib's libm) under QEMU, its UART on a pty: ``servo run --port`` records the same
    logs as the simulated drive, bit for bit, for every kind (about 15 s per 1000 ticks:
    QEMU's UART)."""
    cfg = QEMU_CFG.replace(controller={"kind": kind}, link={"command_latency_ticks": 1, "batch": 2})
    with serve_qemu(mps2_build) as (proc, url):
        fw, sim = servo_run_both(cfg, url, tmp_path)
    assert "servo firmware (mps2-an500)" in (fw / "summary.json").read_text()
    assert_same_logs(fw, sim, kind)


@pytest.mark.slow
@needs_arm
@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_servo_run_loop_on_board_on_the_emulated_cortex_m7_gives_the_simulators_logs(mps2_build, kind, tmp_path):
    cfg = QEMU_CFG.replace(controller={"kind": kind}, link={"command_latency_ticks": 3, "batch": 4})
    with serve_qemu(mps2_build) as (proc, url):
        fw, sim = servo_run_both(cfg, url, tmp_path, "--loop-on-board")
    assert_same_logs(fw, sim, kind)


@pytest.mark.slow
@needs_arm
def test_the_disturbance_on_the_emulated_cortex_m7_is_the_simulators_to_rounding(fw_dir, tmp_path):
    """With the disturbance force on: newlib's sin against glibc's (numpy's here), within
    :data:`NEWLIB_SIN_TOLERANCE`; the quantised position and every discrete column bit
    for bit."""
    cfg = CFG.replace(link={"watchdog_s": 5.0, "timeout_s": 5.0, "ready_timeout_s": 10.0})
    with serve_qemu(build_mps2(cfg, fw_dir)) as (proc, url):
        fw, sim = servo_run_both(cfg, url, tmp_path)
    assert_same_logs(fw, sim, "pi", atol=NEWLIB_SIN_TOLERANCE)


@pytest.mark.slow
@needs_arm
def test_the_emulated_board_falls_to_zero_current_when_its_host_goes_silent(mps2_build, tmp_path):
    """No log line on the target: the board's STATS after its FAULT say it tripped."""
    cfg = FAULT_CFG.replace(link={"watchdog_s": 0.5, "timeout_s": 5.0, "ready_timeout_s": 10.0})
    with serve_qemu(mps2_build) as (proc, url):
        drv = SerialDriver(cfg, f"faulty://{url}?silent_tx=30")
        with pytest.raises(DriverError, match=r"board fault, watchdog at tick \d+: no command for"):
            run_log(cfg, drv, tmp_path, "log")
    assert drv.board_fault is not None and drv.board_fault.code == P.FAULT_WATCHDOG


# ------------------------------------------------------------------- gains at tick boundaries


#: each kind's new gains: the same structure (biquad counts, PES rate), other values
NEW_GAINS = {"pi": {"pi": {"kp": 600.0, "ki": 8e4, "kd": 1.1}}, "track": {"track": {"crossover_hz": 600.0}},
             "nss": {"nss": {"p_gain": 3.0, "d_gain": 50.0}}}  # fmt: skip


def _kind_params(cfg, kind, new=False):
    """The parameter record of ``kind`` under ``cfg`` (its new gains: ``new``)."""
    cfg = cfg.replace(controller={"kind": kind, **(NEW_GAINS[kind] if new else {})})
    return Controller(cfg).records()[3].copy()


def sim_with_gains(cfg, gains, tmp_path, name):
    """The simulated drive's run of ``cfg`` with each gain change written into the
    controller's parameters before its tick's controller runs (after the sample, as on
    the board): the scheduler of ``run_closed_loop`` with one more task."""
    from servo.runtime.scheduler import Scheduler, Task
    from servo.runtime.window import Window

    controller, inputs = Controller(cfg), scenario_inputs(cfg)
    params, changes = controller.records()[3], {g.tick: g.params for g in gains}
    drv = SimDriver(cfg, inputs)
    with drv, RunLog(tmp_path, name, controller.log_columns) as log:
        drv.configure()
        drv.activate()
        sched = Scheduler(drv, controller)
        data = sched.data
        r, u_exc = Window(inputs.reference), Window(inputs.excitation)

        def excitation(k):
            data.r, data.u_exc = r.at(k), u_exc.at(k)

        def gain(k):
            if k in changes:
                params[...] = changes[k]

        def logger(k):
            controller.unchecked_log_row(log.data[log.rows], k, cfg.dt, data.x, data.u_exc)
            log.rows += 1

        sched.before, sched.after = [Task("excitation", 1, excitation), Task("gains", 1, gain)], [Task("log", 1, logger)]
        sched.run(0, cfg.n_ticks, start=True)
    return log.recorded().copy()


@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_gains_changed_at_tick_boundaries_on_the_board_give_the_simulated_drives_run(host_build, kind, tmp_path):
    """New gains at ticks 301 and 302 (inside one batch of 4: the host splits its REFS
    there) and the first gains back at 700: the board applies each before its tick's
    controller runs, acknowledges each, and its log equals the simulated drive's run with
    the same changes, bit for bit."""
    from hil.onboard import GainChange, run_on_board

    cfg = CFG.replace(controller={"kind": kind}, link={"watchdog_s": 2.0, "timeout_s": 2.0, "batch": 4,
                                                       "command_latency_ticks": 3, "loop": "board"})  # fmt: skip
    old, new = _kind_params(cfg, kind), _kind_params(cfg, kind, new=True)
    assert old.tobytes() != new.tobytes()
    gains = [GainChange(301, new), GainChange(302, old), GainChange(303, new), GainChange(700, old)]
    inputs, ticks = scenario_inputs(cfg), np.arange(cfg.n_ticks)
    controller = Controller(cfg)
    with serve_host(host_build) as (proc, url), RunLog(tmp_path, "board", controller.log_columns) as log:
        drv = run_on_board(cfg, url, controller, inputs.reference(ticks), inputs.excitation(ticks), log, gains)
    assert drv.acknowledged == [301, 302, 303, 700]
    board = log.recorded().copy()
    sim = sim_with_gains(cfg, gains, tmp_path, "sim")
    assert np.array_equal(board, sim, equal_nan=True)
    assert np.array_equal(sim_with_gains(cfg, [], tmp_path, "plain"), run_log(cfg, SimDriver(cfg, inputs), tmp_path, "run"),
                          equal_nan=True)  # the helper is run_closed_loop's loop  # fmt: skip
    u = LOG_COLUMNS.index("u")
    plain = sim_with_gains(cfg, [], tmp_path, "plain2")
    assert np.array_equal(board[:301, u], plain[:301, u]) and not np.array_equal(board[301:, u], plain[301:, u])


LOOP_HEAD = struct.Struct("<BBHBBHHH")


def _types(host):
    return [(body[1], body) for body in host.dec.feed(host.out())]


def _loop_running(lib, kind, every=0, b=1):
    """A board running ``kind`` itself (batch ``b``, a log row every ``every`` ticks, 0:
    the field a host of before sends), tick 0 run; returns (host, kind code)."""
    from hil.onboard import CHUNK, KIND_CODES, LOOP

    host = _fresh(lib)
    ready = host.configure(watchdog_ms=50, b=b, d=max(0, b - 1))[-1]
    ctl = Controller(CFG.replace(controller={"kind": kind}))
    ctl.start(ready.x, ready.v, ready.i)
    data, code = ctl.buf.tobytes(), KIND_CODES[kind]
    for off in range(0, len(data), CHUNK):  # the records in frames of at most 1000 bytes
        host.send(lambda s: LOOP_HEAD.pack(P.VERSION, LOOP, s, code, 0, off, len(data), every) + data[off : off + CHUNK])
    host.send(P.start)
    _refs(host, 0)
    assert lib.fwt_state() == ACTIVE
    host.out()
    return host, code


def _refs(host, k):
    from hil.onboard import REFS

    host.send(lambda s: struct.pack("<BBHIBBHdd", P.VERSION, REFS, s, k, 1, 0, 0, 0.0, 0.0))


def _gains(host, tick, code, params):
    from hil.onboard import GAINS

    body = params.tobytes()
    host.send(lambda s: struct.pack("<BBHIBBHI", P.VERSION, GAINS, s, tick, code, 0, len(body), 0) + body)


def test_gains_are_applied_at_their_tick_and_acknowledged(lib):
    from hil.onboard import GAINS_ACK, LOG

    host, code = _loop_running(lib, "pi")
    _gains(host, 3, code, _kind_params(CFG, "pi", new=True))
    assert _types(host) == []  # pending: nothing until tick 3 runs
    for k in (1, 2, 3):
        _refs(host, k)
    kinds = [t for t, _ in _types(host)]
    assert kinds == [LOG, LOG, GAINS_ACK, LOG]  # acknowledged when applied, before tick 3's row
    assert lib.fwt_state() == ACTIVE and lib.fwt_applied() != 0.0


@pytest.mark.parametrize("every,b", [(1, 1), (3, 1), (3, 2), (7, 4)])
def test_the_board_sends_every_nth_row_in_batches(lib, every, b):
    """LOOP's log period ``every``: the board sends the rows of ticks 0, every, 2 every ..
    only, ``b`` to a LOG frame, each frame once its last row exists; the other ticks run
    and send nothing."""
    from hil.onboard import LOG

    host, code = _loop_running(lib, "track", every=every, b=b)
    for k in range(1, 6 * every * b):
        _refs(host, k)
    logs = [body for t, body in _types(host) if t == LOG]
    assert lib.fwt_state() == ACTIVE
    first = 1 if b == 1 else 0  # a frame of tick 0 alone went out (and was read) with tick 0
    assert len(logs) == 6 - first
    heads = [struct.unpack_from("<IBB", body, 4) for body in logs]
    assert [h[0] for h in heads] == [m * b * every for m in range(first, 6)]
    assert all(h[1] == b and h[2] == 13 for h in heads)
    rows = np.concatenate([np.frombuffer(body, "<f8", offset=12).reshape(b, 13) for body in logs])
    assert np.array_equal(rows[:, 0], np.arange(first * b * every, 6 * b * every, every))  # the tick column


def test_a_log_period_that_changes_between_loop_pieces_is_refused(lib):
    from hil.onboard import CHUNK, KIND_CODES, LOOP

    host = _fresh(lib)
    ready = host.configure(watchdog_ms=50)[-1]
    ctl = Controller(CFG.replace(controller={"kind": "track"}))
    ctl.start(ready.x, ready.v, ready.i)
    data, code = ctl.buf.tobytes(), KIND_CODES["track"]
    assert len(data) > CHUNK
    for off, every in ((0, 4), (CHUNK, 5)):
        host.send(lambda s: LOOP_HEAD.pack(P.VERSION, LOOP, s, code, 0, off, len(data), every) + data[off : off + CHUNK])
    faults = [P.parse(body)[2] for t, body in _types(host) if t == P.FAULT]
    assert [f.code for f in faults] == [P.FAULT_CONFIG] and "log period" in faults[0].text
    assert lib.fwt_state() == FAULTED and lib.fwt_applied() == 0.0


def _bad(kind, how):
    p = _kind_params(CFG, kind, new=True)
    if how == "nan":
        p[p.dtype.names[1]] = math.nan
    elif how == "negative_gain":
        p["kp"] = -1.0
    elif how == "setpoint_weight":
        p["b"] = 1.5
    elif how == "other_period":
        p["dt"] *= 2.0
    elif how == "unstable_biquad":
        p["sos_fast"][0, 0, 5] = 1.01  # a pole outside the unit circle
    elif how == "other_structure":
        p["n_fast"] -= 1.0
    elif how == "no_output":
        p["u_n_max"] = 0.0
    return p


@pytest.mark.parametrize("kind,how", [("pi", "nan"), ("pi", "negative_gain"), ("pi", "setpoint_weight"),
                                      ("pi", "other_period"), ("pi", "no_output"), ("track", "nan"),
                                      ("track", "unstable_biquad"), ("track", "other_structure"),
                                      ("nss", "no_output"), ("pi", "past_tick"), ("pi", "two_pending"),
                                      ("pi", "other_kind")])  # fmt: skip
def test_gains_out_of_range_are_a_fault_at_zero_current(lib, kind, how):
    host, code = _loop_running(lib, kind)
    if how == "past_tick":
        _gains(host, 0, code, _kind_params(CFG, kind, new=True))  # tick 0 has run
    elif how == "two_pending":
        _gains(host, 5, code, _kind_params(CFG, kind, new=True))
        _gains(host, 6, code, _kind_params(CFG, kind, new=True))
    elif how == "other_kind":
        _gains(host, 5, 2, _kind_params(CFG, "track", new=True))
    else:
        _gains(host, 5, code, _bad(kind, how))
    faults = [P.parse(body)[2] for t, body in _types(host) if t == P.FAULT]
    assert [f.code for f in faults] == [P.FAULT_COMMAND], faults
    assert "GAINS for tick" in faults[0].text
    assert lib.fwt_state() == FAULTED and lib.fwt_applied() == 0.0


# ------------------------------------------------------------------- a real board's port


def test_a_port_provides_four_hal_functions_and_the_stub_links(tmp_path):
    """The session (board.c) needs exactly the four functions of hal.h from a board;
    hal_board_stub.c provides them: the portable sources, the stub and a main link."""
    cc = find_cc()
    board_o = tmp_path / "board.o"
    subprocess.run([cc, "-std=c99", "-c", "-I", str(ROOT), str(ROOT / "board.c"), "-o", str(board_o)], check=True)
    undefined = subprocess.run(["nm", "-u", str(board_o)], capture_output=True, text=True, check=True).stdout.split()
    assert {s for s in undefined if s.startswith("hal_")} == {"hal_read_position", "hal_write_current", "hal_now_us",
                                                              "hal_stream"}  # fmt: skip
    main = tmp_path / "main.c"
    main.write_text('#include "board.h"\nint main(void)\n{\n    static board bd;\n'
                    '    board_info info = {"port", 50000.0, 1.0, 0.0, 0, 0, 0};\n    board_init(&bd, &info);\n'
                    '    board_poll(&bd);\n    board_tick(&bd);\n    return (int)bd.state;\n}\n')  # fmt: skip
    sources = [str(ROOT / s) for s in ("cobs.c", "crc32.c", "board.c", "controller.c", "dahl.c", "hal_board_stub.c")]
    r = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-DSERVO_FW_PORT", "-I", str(ROOT), *sources,
                        str(main), "-o", str(tmp_path / "port"), "-lm"], capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert subprocess.run([str(tmp_path / "port")]).returncode == IDLE  # power-up: IDLE, zero current
    r = subprocess.run([cc, "-std=c99", "-fsyntax-only", "-I", str(ROOT), str(ROOT / "hal_board_stub.c")],
                       capture_output=True, text=True)  # fmt: skip
    assert r.returncode != 0 and "is a template" in r.stderr  # not built by mistake


def test_the_loop_on_the_board_is_refused_by_a_board_without_it(tmp_path):
    """The Python emulator runs no controller: its INFO lacks the capability, and the host
    stops with one line before READY's drive is held."""
    from hil.emulator import start_in_thread
    from hil.onboard import OnBoardDriver

    cfg = CFG.replace(link={"loop": "board", "timeout_s": 2.0})
    with start_in_thread(Board(cfg), "tcp") as url:
        drv = OnBoardDriver(cfg, url)
        with pytest.raises(DriverError, match=r"does not run the loop itself .*use link.loop = \"host\""):
            drv.configure()


@pytest.mark.slow  # a servo run in-process against the host build, and the simulated drive's run
def test_servo_run_gains_changes_the_boards_gains_at_their_ticks(host_build, tmp_path):
    """``servo run --port URL --loop-on-board --gains 0.006=new.toml --gains 0.014=old.toml``:
    the board switches to the file's gains at tick 300 and back at 700, and the log is the
    simulated drive's run with the same changes, bit for bit."""
    from servo.cli import main

    cfg = CFG.replace(controller={"kind": "pi"}, link={"watchdog_s": 2.0, "timeout_s": 2.0, "batch": 4,
                                                       "command_latency_ticks": 3, "loop": "board"})  # fmt: skip
    (tmp_path / "cfg.toml").write_text(to_toml(cfg))
    (tmp_path / "new.toml").write_text("[controller.pi]\nkp = 600.0\nki = 8e4\nkd = 1.1\n")
    (tmp_path / "old.toml").write_text(f"[controller.pi]\nkp = {cfg.controller.pi.kp!r}\nki = {cfg.controller.pi.ki!r}\n"
                                       f"kd = {cfg.controller.pi.kd!r}\n")  # fmt: skip
    fw = tmp_path / "fw"
    with serve_host(host_build) as (proc, url):
        assert main(["run", "--config", str(tmp_path / "cfg.toml"), "--port", url, "--out", str(fw), "--quiet",
                     "--compensation", "on", "--gains", f"0.006={tmp_path / 'new.toml'}",
                     "--gains", f"0.014={tmp_path / 'old.toml'}"]) == 0  # fmt: skip
    from hil.onboard import GainChange

    gains = [GainChange(300, _kind_params(cfg, "pi", new=True)), GainChange(700, _kind_params(cfg, "pi"))]
    sim = sim_with_gains(cfg, gains, tmp_path, "sim")
    board = np.load(fw / "log_compensated.npz")
    assert np.array_equal(np.column_stack([board[c] for c in LOG_COLUMNS]), sim, equal_nan=True)
    plain = sim_with_gains(cfg, [], tmp_path, "plain")
    u = LOG_COLUMNS.index("u")
    assert np.array_equal(sim[:300, u], plain[:300, u]) and not np.array_equal(sim[300:700, u], plain[300:700, u])


@pytest.mark.parametrize("argv,says", [
    (["--gains", "0.006=G"], r"--gains needs --port URL and --loop-on-board"),
    (["--port", "P", "--loop-on-board", "--gains", "soon=G"], r"--gains 'soon=.*': give S=TOML"),
    (["--port", "P", "--loop-on-board", "--gains", "inf=G"], r"--gains 'inf=.*': give S=TOML"),
    (["--port", "P", "--loop-on-board", "--gains", "0.006=nowhere.toml"], r"cannot read the gains file"),
    (["--port", "P", "--loop-on-board", "--gains", "0.006=K"], r"for controller.kind = 'track', the run's is 'pi'"),
    (["--port", "P", "--loop-on-board", "--gains", "5=G"], r"a gain change at 5 s is outside the run"),
    (["--port", "P", "--loop-on-board", "--gains", "0.006=C"], r"gains file .* has no \[controller\] table"),
])  # fmt: skip
def test_bad_gains_on_the_command_line_are_one_line_and_write_nothing(argv, says, tmp_path, capsys):
    from servo.cli import main

    (tmp_path / "G").write_text("[controller.pi]\nkp = 600.0\n")
    (tmp_path / "K").write_text("[controller]\nkind = \"track\"\n")
    (tmp_path / "C").write_text("[run]\nseed = 3\n")
    argv = [a.replace("=G", f"={tmp_path / 'G'}").replace("=K", f"={tmp_path / 'K'}").replace("=C", f"={tmp_path / 'C'}")
            for a in argv]  # fmt: skip
    (tmp_path / "cfg.toml").write_text(to_toml(CFG.replace(controller={"kind": "pi"})))
    out = tmp_path / "out"
    rc = main(["run", "--config", str(tmp_path / "cfg.toml"), "--out", str(out), "--quiet", *argv])
    err = capsys.readouterr().err
    assert rc != 0 and re.search(says, err) and err.count("\n") == 1 and err.startswith("servo: error: "), err
    assert not out.exists() and not (tmp_path / "out.incomplete").exists()

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
import os
import shutil
import signal
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
CFG = comparable(Config().replace(run={"duration_s": 0.02},
                                  scenario={"step_times": [0.005, 0.012], "step_positions": [2e-6, 0.0]}))  # fmt: skip
#: a drive with every effect the plant models, for the kernel vectors
FULL = comparable(Config().replace(
    drive={"input_delay_s": 1.3 / RATE, "cogging": 2e-3, "alpha": 0.7, "fc_asymmetry": 0.1, "b_asymmetry": 0.05, "kf_linear": 0.05, "kf_quadratic": -0.1,
           "sensor_cutoff_hz": 3000.0, "Fs": 0.004, "Fc": 0.003}))  # fmt: skip
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
    force-constant variation, Stribeck friction, Dahl hysteresis, the sensor low-pass,
    quantiser and hard stops (the commands drive the arm into them)."""
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


def test_the_controller_records_header_is_the_dtypes():
    from bench.cref import CONTROLLER_RECORDS, records_header

    text = (ROOT / "records.h").read_text()
    assert records_header(CONTROLLER_RECORDS) in text  # regenerate it with bench/cref.py if a dtype changed


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
                                       "authority": 0.5})  # fmt: skip
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
    assert info.caps == P.CAP_VELOCITY | P.CAP_CURRENT | P.CAP_LOCKSTEP and info.max_batch == 32
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
_CONFIGS = st.builds(P.ConfigMsg, st.sampled_from([2, 2, 2, 1, 3]), _around(8, 32), st.integers(0, 1100),
                     _around(32, P.MAX_WATCHDOG_US), _around(16, 1000), st.sampled_from([RATE, RATE, 40_000.0, math.nan]),
                     _u(16) | st.integers(P.MAX_READY_TIMEOUT_MS - 2, P.MAX_READY_TIMEOUT_MS + 2))  # fmt: skip


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


@pytest.mark.slow  # two runs of servo run in-process, 10-15 s on a loaded machine
def test_servo_run_port_against_the_firmware_gives_the_simulators_logs(host_build, tmp_path):
    cfg = CFG.replace(link={"watchdog_s": 2.0, "timeout_s": 2.0})
    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text(to_toml(cfg))
    from servo.cli import main

    with serve_host(host_build) as (proc, url):
        assert main(["run", "--config", str(cfg_file), "--port", url, "--out", str(tmp_path / "fw"), "--quiet"]) == 0
        lines = [read_line(proc, 2.0) for _ in range(4)]
    assert main(["run", "--config", str(cfg_file), "--out", str(tmp_path / "sim"), "--quiet"]) == 0
    assert all("drive at zero current" in line for line in lines[1::2]), lines
    for label in ("compensated", "uncompensated"):
        fw, sim = np.load(tmp_path / "fw" / f"log_{label}.npz"), np.load(tmp_path / "sim" / f"log_{label}.npz")
        for col in LOG_COLUMNS:
            assert np.array_equal(fw[col], sim[col], equal_nan=True), (label, col)


@pytest.mark.parametrize("kind", ["pi", "track", "nss"])
def test_the_loop_on_the_board_logs_the_simulated_drives_run(host_build, kind, tmp_path):
    """The controller kind runs on the board (its records sent after READY, the reference
    streamed ahead, log rows streamed back): the log equals the simulated drive's run of
    the same config with no link latency, bit for bit (same operations, same order)."""
    from hil.onboard import run_on_board

    cfg = CFG.replace(controller={"kind": kind}, link={"watchdog_s": 2.0, "timeout_s": 2.0, "batch": 4,
                                                       "command_latency_ticks": 3})  # fmt: skip
    inputs = scenario_inputs(cfg)
    ticks = np.arange(cfg.n_ticks)
    controller = Controller(cfg)
    with serve_host(host_build) as (proc, url), RunLog(tmp_path, "board", controller.log_columns) as log:
        run_on_board(cfg, url, controller, inputs.reference(ticks), inputs.excitation(ticks), log)
    board = log.recorded().copy()
    sim_cfg = cfg.replace(link={"command_latency_ticks": 0, "batch": 1})
    sim = run_log(sim_cfg, SimDriver(sim_cfg, scenario_inputs(sim_cfg)), tmp_path, "sim")
    assert board.shape == sim.shape
    assert np.array_equal(board, sim, equal_nan=True)
    assert np.ptp(sim[:, LOG_COLUMNS.index("x")]) > 1e-6


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
    return build_mps2(CFG, fw_dir)


@pytest.mark.slow
@needs_arm
def test_servo_run_port_on_the_emulated_cortex_m7_gives_the_simulators_logs(mps2_build, tmp_path):
    """The firmware cross-compiled for the MPS2 AN500 (Cortex-M7, double-precision FPU,
    newlib's libm) under QEMU, its UART on a pty: ``servo run --port`` records the same
    logs as the simulated drive, bit for bit (about 15 s per 1000 ticks: QEMU's UART)."""
    cfg = CFG.replace(link={"watchdog_s": 5.0, "timeout_s": 5.0, "ready_timeout_s": 10.0})
    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text(to_toml(cfg))
    from servo.cli import main

    with serve_qemu(mps2_build) as (proc, url):
        assert main(["run", "--config", str(cfg_file), "--port", url, "--out", str(tmp_path / "fw"), "--quiet"]) == 0
    assert main(["run", "--config", str(cfg_file), "--out", str(tmp_path / "sim"), "--quiet"]) == 0
    summary = (tmp_path / "fw" / "summary.json").read_text()
    assert "servo firmware (mps2-an500)" in summary
    for label in ("compensated", "uncompensated"):
        fw, sim = np.load(tmp_path / "fw" / f"log_{label}.npz"), np.load(tmp_path / "sim" / f"log_{label}.npz")
        for col in LOG_COLUMNS:
            assert np.array_equal(fw[col], sim[col], equal_nan=True), (label, col)


@pytest.mark.slow
@needs_arm
@pytest.mark.parametrize("kind", ["track", "nss"])
def test_the_other_controller_kinds_on_the_emulated_cortex_m7(mps2_build, kind, tmp_path):
    cfg = CFG.replace(controller={"kind": kind}, link={"watchdog_s": 5.0, "timeout_s": 5.0, "command_latency_ticks": 1,
                                                       "batch": 2})  # fmt: skip
    with serve_qemu(mps2_build) as (proc, url):
        hil = run_log(cfg, SerialDriver(cfg, url), tmp_path, "fw")
    sim = run_log(cfg, SimDriver(cfg, scenario_inputs(cfg)), tmp_path, "sim")
    assert np.array_equal(hil, sim, equal_nan=True)


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


@pytest.mark.slow
@needs_arm
def test_the_loop_on_the_emulated_cortex_m7_logs_the_simulated_drives_run(mps2_build, tmp_path):
    from hil.onboard import run_on_board

    cfg = CFG.replace(controller={"kind": "nss"}, link={"watchdog_s": 5.0, "timeout_s": 5.0, "batch": 4,
                                                        "command_latency_ticks": 3})  # fmt: skip
    inputs = scenario_inputs(cfg)
    ticks = np.arange(cfg.n_ticks)
    controller = Controller(cfg)
    with serve_qemu(mps2_build) as (proc, url), RunLog(tmp_path, "board", controller.log_columns) as log:
        run_on_board(cfg, url, controller, inputs.reference(ticks), inputs.excitation(ticks), log)
    sim_cfg = cfg.replace(link={"command_latency_ticks": 0, "batch": 1})
    sim = run_log(sim_cfg, SimDriver(sim_cfg, scenario_inputs(sim_cfg)), tmp_path, "sim")
    assert np.array_equal(log.recorded(), sim, equal_nan=True)

"""The loop on the board: the firmware runs the controller kind at its fixed rate, the
host supervises (``docs/protocol.md`` section 9, ``docs/firmware.md``).

After READY the host sends the controller's four records (stage and kind, state and
parameters, already started bumplessly from READY's sample and holding current) in
LOOP frames, then START; from then on it sends the reference and excitation of each
tick ahead in REFS frames, and the board answers each batch of ``b`` ticks with a LOG
frame of ``b`` rows of the run log (the columns of :data:`kernels.compose.LOG_COLUMNS`
and the kind's).  New parameters of the kind (:class:`GainChange`) go in a GAINS frame
before the REFS of their tick; the board applies them before that tick's controller
runs and acknowledges them (GAINS_ACK); it refuses values out of range with a fault, at
zero current.  Lockstep boards only, for now (INFO capability :data:`hil.protocol.CAP_LOOP`):
the board runs a tick once its reference is there.

:class:`OnBoardDriver` is the driver ``servo run`` uses with ``link.loop = "board"``
(:attr:`~servo.runtime.driver.Driver.closes_loop`); :func:`run_on_board` the same run
from arrays.
"""
from __future__ import annotations

import math
import struct
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from hil import protocol as P
from hil.serialdriver import SerialDriver
from kernels.compose import STATS_SIZE, error_stats
from servo.config import Config
from servo.errors import ConfigError, DriverError, first_line
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.scenarios import ArrayInputs, Inputs

LOOP, REFS, GAINS, LOG, GAINS_ACK = 0x06, 0x07, 0x08, 0x87, 0x88
KIND_CODES = {"pi": 1, "track": 2, "nss": 2}
"""The firmware's code of each kind's kernels (two-rate cascade: 2)."""
_LOOP_HEAD = struct.Struct("<BBHBBHHH")  # header, kind, reserved, byte offset, total bytes, log period
_LOG_HEAD = struct.Struct("<BBHIBBH")  # header, tick0, rows, columns, reserved
_GAINS_HEAD = struct.Struct("<BBHIBBHI")  # header, tick, kind, reserved, bytes, reserved
_ACK = struct.Struct("<BBHIBBH")  # header, tick, kind, reserved
CHUNK = 1000 - _LOOP_HEAD.size
REFS_MAX = 32
"""Ticks of reference per REFS frame (the protocol's largest; the board's cost per tick
falls with it)."""


def link_log_every(cfg: Config) -> int:
    """Ticks between the log rows the board sends (LOOP's log period): every
    ``run.log_every``-th tick's row for the log and every ``run.estimator_every``-th for
    the tracking-error statistics, so their greatest common divisor."""
    return math.gcd(cfg.run.log_every, cfg.run.estimator_every)


@dataclass(frozen=True)
class GainChange:
    """New parameters of the running kind from tick ``tick`` on: ``params``, a record of
    the kind's ``PARAMS`` dtype (e.g. ``Controller(new_cfg).records()[3]``, the gains of
    another config of the same kind and structure)."""

    tick: int
    params: np.ndarray


def gain_change(cfg: Config, t_s: float, controller: dict) -> GainChange:
    """The change, ``t_s`` seconds into ``cfg``'s run, to the gains that ``controller``
    gives (a config's ``[controller]`` table, e.g. ``{"pi": {"kp": 600.0}}``, over
    ``cfg``'s): the running kind's parameter record of ``cfg.replace(controller=...)``
    from tick ``round(t_s * run.sample_rate_hz)`` on.  Raises ``ConfigError`` (one line)
    for another kind, a structure the board cannot switch to, or a time outside the run."""
    new = cfg.replace(controller=controller)
    if new.controller.kind != cfg.controller.kind:
        raise ConfigError(f"config: a gain change at {t_s:g} s is for controller.kind = {new.controller.kind!r}, "
                          f"the run's is {cfg.controller.kind!r} (the board changes gains, not kinds)")  # fmt: skip
    tick = round(t_s * cfg.run.sample_rate_hz)
    if not 0 < tick < cfg.n_ticks:
        raise ConfigError(f"config: a gain change at {t_s:g} s is outside the run (0 .. {cfg.n_ticks * cfg.dt:g} s)")
    old, params = Controller(cfg).records()[3], Controller(new).records()[3].copy()
    if params.dtype != old.dtype or params.shape != old.shape:
        raise ConfigError(f"config: the gain change at {t_s:g} s changes the structure of {cfg.controller.kind}'s "
                          "parameters")  # fmt: skip
    return GainChange(tick, params)


def gain_changes_from_files(cfg: Config, changes: Sequence[tuple[float, str | Path]]) -> list[GainChange]:
    """:func:`gain_change` of each ``(t_s, path)``: the ``[controller]`` table of the TOML
    file at ``path`` (its other tables are ignored), from ``t_s`` seconds on."""
    out = []
    for t_s, path in changes:
        try:
            data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, ValueError) as exc:
            raise ConfigError(f"config: cannot read the gains file {path}: {first_line(exc)}") from None
        if not isinstance(data.get("controller"), dict):
            raise ConfigError(f"config: the gains file {path} has no [controller] table")
        out.append(gain_change(cfg, t_s, data["controller"]))
    return out


class OnBoardDriver(SerialDriver):
    """The board at ``url`` running ``cfg.controller.kind`` itself; the host sends the
    references and gain changes and records the board's log (:meth:`run_loop`)."""

    closes_loop = True

    def __init__(self, cfg: Config, url: str, gains: Sequence[GainChange] = ()):
        super().__init__(cfg, url)
        self.gains = sorted(gains, key=lambda g: g.tick)
        self.acknowledged: list[int] = []
        """Ticks of the gain changes the board acknowledged, in order."""
        self.log_frames = 0
        """LOG frames received (each of ``link.batch`` rows, a row every
        :func:`link_log_every` ticks)."""

    def _on_configure(self):
        info = super()._on_configure()
        if not self.board_info.caps & P.CAP_LOOP:
            raise DriverError(f"link: the board at {self.url} ('{self.board_info.name}') does not run the loop itself "
                              "(no loop-on-board capability in its INFO); use link.loop = \"host\"")  # fmt: skip
        self._check_rows(self.cfg)  # before anything is written
        return replace(info, command_latency_ticks=self.cfg.link.loop_latency_ticks)  # none in the board's loop

    def _check_rows(self, cfg: Config) -> int:
        """The board's log period for ``cfg`` (:func:`link_log_every`), if its rows fill
        whole LOG frames of ``link.batch`` rows and the period fits LOOP's field."""
        n, b, every = cfg.n_ticks, self.b, link_log_every(cfg)
        rows_total = -(-n // every)  # ticks 0, every, 2 every, ... below n
        if rows_total % b:
            raise DriverError(f"link: the loop on the board sends whole LOG frames of link.batch = {b} rows: the run's "
                              f"{rows_total} rows (one every {every} ticks of {n}) are not a multiple of {b}")  # fmt: skip
        if every > 0xFFFF:
            raise DriverError(f"link: the board's log period, {every} ticks (run.log_every and run.estimator_every's "
                              "greatest common divisor), is over 65535")  # fmt: skip
        return every

    def run_loop(self, cfg: Config, controller: Controller, inputs: Inputs, log: RunLog, stats: np.ndarray,
                 watchdog=None) -> None:  # fmt: skip
        """Run ``cfg.n_ticks`` ticks of ``controller``'s kind on the board: the records
        after READY, START, then the reference and excitation of each tick (sampled every
        ``run.excitation_every`` ticks and held, as the host's loop does) and the gain
        changes; the board's rows every ``run.log_every`` ticks go to ``log``, the
        tracking error every ``run.estimator_every`` ticks to ``stats``
        (:func:`kernels.compose.error_stats`), and ``watchdog`` looks at the rows."""
        n, b = cfg.n_ticks, self.b
        every = self._check_rows(cfg)
        if self.gains and not (0 <= self.gains[0].tick and self.gains[-1].tick < n):
            raise DriverError(f"link: a gain change outside the run's ticks 0..{n - 1}")
        params = controller.records()[3]
        for g in self.gains:
            if g.params.dtype != params.dtype or g.params.shape != params.shape:
                raise DriverError(f"link: the gain change of tick {g.tick} is not a record of {cfg.controller.kind}'s "
                                  "parameters")  # fmt: skip
        controller.start(self._x, self._v, self._i)  # READY's sample and holding current
        data = controller.buf.tobytes()
        code = KIND_CODES[cfg.controller.kind]
        for off in range(0, len(data), CHUNK):
            self._send(_LOOP_HEAD.pack(P.VERSION, LOOP, self._tx_seq, code, 0, off, len(data), every)
                       + data[off : off + CHUNK])  # fmt: skip
        self.activate()
        cols = len(controller.log_columns)
        e_col = list(controller.log_columns).index("e")
        hold, log_every, est_every = cfg.run.excitation_every, cfg.run.log_every, cfg.run.estimator_every
        pending = list(self.gains)
        frames = 0  # LOG frames read
        for k0 in range(0, n, REFS_MAX):
            ticks = np.arange(k0, min(k0 + REFS_MAX, n))
            held = ticks - ticks % hold
            r, u_exc = inputs.reference(held), inputs.excitation(held)
            start, m = 0, ticks.shape[0]
            while pending and pending[0].tick < k0 + m:  # the REFS split at each change
                g = pending.pop(0)
                if g.tick - k0 > start:
                    self._refs(k0 + start, r[start : g.tick - k0], u_exc[start : g.tick - k0])
                    start = g.tick - k0
                body = g.params.tobytes()
                self._send(_GAINS_HEAD.pack(P.VERSION, GAINS, self._tx_seq, g.tick, code, 0, len(body), 0) + body)
            self._refs(k0 + start, r[start:], u_exc[start:])
            while frames < -(-(k0 + m) // every) // b:  # the LOG frames the ticks sent so far complete
                rows = self._log_frame(frames * b * every, b, cols, every)
                frames += 1
                self.log_frames = frames
                for i, row in enumerate(rows):
                    k = (frames - 1) * b * every + i * every
                    if k % est_every == 0:
                        error_stats(stats, row[e_col])
                    if k % log_every == 0:
                        log.data[log.rows] = row
                        log.rows += 1
                        if watchdog is not None:
                            watchdog.maybe_look(log)
                        else:
                            log.maybe_flush()
        while len(self.acknowledged) < len(self.gains):  # changes after the last logged row
            self._k_frame = n
            kind, body = self._next_body(time.perf_counter_ns() + int(self.timeout_s * 1e9), "GAINS_ACK")
            if kind != GAINS_ACK or len(body) != _ACK.size:
                self._parse(body)
                raise DriverError(f"link: a {P.TYPE_NAMES.get(kind, hex(kind))} frame from the board, not GAINS_ACK")
            self.acknowledged.append(_ACK.unpack(body)[3])
        if self.acknowledged != [g.tick for g in self.gains]:
            raise DriverError(f"link: the board acknowledged gain changes at ticks {self.acknowledged}, the host "
                              f"sent them for {[g.tick for g in self.gains]}")  # fmt: skip

    def _refs(self, k0: int, r: np.ndarray, u_exc: np.ndarray) -> None:
        pairs = np.empty(2 * r.shape[0])
        pairs[0::2], pairs[1::2] = r, u_exc
        self._send(struct.pack(f"<BBHIBBH{pairs.shape[0]}d", P.VERSION, REFS, self._tx_seq, k0, r.shape[0], 0, 0,
                               *pairs))  # fmt: skip

    def _log_frame(self, k0: int, b: int, cols: int, every: int) -> np.ndarray:
        """The LOG frame of ticks ``k0, k0 + every, ..`` (``b`` rows: ``(b, cols)``);
        acknowledgements of gain changes before it are recorded."""
        self._k_frame = k0  # the tick the link's error messages name
        while True:
            kind, body = self._next_body(time.perf_counter_ns() + int(self.timeout_s * 1e9), "LOG")
            if kind == GAINS_ACK and len(body) == _ACK.size:
                self.acknowledged.append(_ACK.unpack(body)[3])
                continue
            if kind != LOG:
                self._parse(body)  # a FAULT raises with its text
                raise DriverError(f"link: a {P.TYPE_NAMES.get(kind, hex(kind))} frame from the board, not LOG")
            _, _, _, tick0, rows, ncols, _ = _LOG_HEAD.unpack_from(body)
            if tick0 != k0 or rows != b or ncols != cols or len(body) != _LOG_HEAD.size + 8 * b * cols:
                raise DriverError(f"link: LOG frame of tick {tick0}, {rows} x {ncols}, expected {k0}, {b} x {cols} "
                                  f"(a row every {every} ticks)")  # fmt: skip
            return np.frombuffer(body, "<f8", offset=_LOG_HEAD.size).reshape(b, cols)


def run_on_board(cfg: Config, url: str, controller: Controller, reference: np.ndarray, excitation: np.ndarray,
                 log: RunLog, gains: Sequence[GainChange] = ()) -> OnBoardDriver:  # fmt: skip
    """Run ``cfg.n_ticks`` ticks of ``controller``'s kind on the board at ``url`` with the
    reference (m) and excitation (A) of each tick and the gain changes ``gains``; the
    board's log rows go to ``log``.  Returns the driver (closed), for its counters."""
    drv = OnBoardDriver(cfg, url, gains)
    with drv:
        drv.configure()
        drv.run_loop(cfg, controller, ArrayInputs(reference, excitation), log, np.zeros(STATS_SIZE))
    return drv

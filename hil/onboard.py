"""The loop on the board: the firmware runs the controller kind at its fixed rate, the
host supervises (``docs/protocol.md`` section 9, ``docs/firmware.md``).

After READY the host sends the controller's four records (stage and kind, state and
parameters, already started bumplessly from READY's sample and holding current) in
LOOP frames, then START; from then on it sends the reference and excitation of each
tick ahead in REFS frames, and the board answers each batch of ``b`` ticks with a LOG
frame of ``b`` rows of the run log (the columns of :data:`kernels.compose.LOG_COLUMNS`
and the kind's).  Lockstep boards only, for now: the board runs a tick once its
reference is there.
"""
from __future__ import annotations

import struct

import numpy as np

from hil import protocol as P
from hil.serialdriver import SerialDriver
from servo.config import Config
from servo.errors import DriverError
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller

LOOP, REFS, LOG = 0x06, 0x07, 0x87
KIND_CODES = {"pi": 1, "track": 2, "nss": 2}
"""The firmware's code of each kind's kernels (two-rate cascade: 2)."""
_LOOP_HEAD = struct.Struct("<BBHBBHHH")  # header, kind, reserved, byte offset, total bytes, reserved
_LOG_HEAD = struct.Struct("<BBHIBBH")  # header, tick0, rows, columns, reserved
CHUNK = 1000 - _LOOP_HEAD.size


def run_on_board(cfg: Config, url: str, controller: Controller, reference: np.ndarray, excitation: np.ndarray,
                 log: RunLog) -> None:  # fmt: skip
    """Run ``cfg.n_ticks`` ticks of ``controller``'s kind on the board at ``url`` with the
    reference (m) and excitation (A) of each tick; the board's log rows go to ``log``."""
    n, b = cfg.n_ticks, cfg.link.batch
    if cfg.run.excitation_every != 1 or cfg.run.log_every != 1:
        raise DriverError("link: the loop on the board takes a reference every tick and logs every tick "
                          "(run.excitation_every = run.log_every = 1)")  # fmt: skip
    if n % b:
        raise DriverError(f"link: the loop on the board needs run ticks ({n}) a multiple of link.batch ({b})")
    drv = SerialDriver(cfg, url)
    with drv:
        drv.configure()
        controller.start(drv._x, drv._v, drv._i)  # READY's sample and holding current
        data = controller.buf.tobytes()
        for off in range(0, len(data), CHUNK):
            part = data[off : off + CHUNK]
            drv._send(_LOOP_HEAD.pack(P.VERSION, LOOP, drv._tx_seq, KIND_CODES[cfg.controller.kind], 0, off,
                                      len(data), 0) + part)  # fmt: skip
        drv.activate()
        cols = len(controller.log_columns)
        row_struct = struct.Struct("<" + "d" * (b * cols))
        refs = struct.Struct("<BBHIBBH" + "d" * (2 * b))
        inter = np.empty(2 * b)
        for k0 in range(0, n, b):
            inter[0::2], inter[1::2] = reference[k0 : k0 + b], excitation[k0 : k0 + b]
            drv._send(refs.pack(P.VERSION, REFS, drv._tx_seq, k0, b, 0, 0, *inter))
            kind, body = drv._next_body(_deadline(drv), "LOG")
            if kind != LOG:
                drv._parse(body)  # a FAULT raises with its text
                raise DriverError(f"link: a {P.TYPE_NAMES.get(kind, hex(kind))} frame from the board, not LOG")
            _, _, _, tick0, rows, ncols, _ = _LOG_HEAD.unpack_from(body)
            if tick0 != k0 or rows != b or ncols != cols or len(body) != _LOG_HEAD.size + row_struct.size:
                raise DriverError(f"link: LOG frame of tick {tick0}, {rows} x {ncols}, expected {k0}, {b} x {cols}")
            vals = np.frombuffer(body, "<f8", offset=_LOG_HEAD.size).reshape(b, cols)
            for row in vals:
                log.data[log.rows] = row
                log.rows += 1
                log.maybe_flush()
        drv.deactivate()


def _deadline(drv: SerialDriver) -> int:
    import time

    return time.perf_counter_ns() + int(drv.timeout_s * 1e9)

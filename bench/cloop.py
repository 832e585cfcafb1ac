"""The fast path's closed loop in C with its logging (``bench/c/closed_log.c``), built
as :mod:`bench.cref` builds the reference and loaded with ctypes."""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench import cref

SOURCE = cref.SOURCE.with_name("closed_log.c")
_P, _I = ctypes.c_void_p, ctypes.c_int64


def _ptr(a: np.ndarray) -> int:
    if not a.flags.c_contiguous:
        raise ValueError("the C loop reads contiguous arrays")
    return a.ctypes.data


@dataclass
class CLoggedLoop:
    """``ref_closed_loop_logged``: ticks ``k0 .. k0+n-1`` of the PI kind's closed loop,
    the estimator and the log rows, in C.  The arguments are those of the Numba
    ``closed_loop`` of :mod:`kernels.compose` (the plant, the link's latency queue, the
    controller's records, the inputs of the ticks, the stats and the log)."""

    lib: ctypes.CDLL
    flags: list[str]

    @classmethod
    def load(cls, workdir: Path, cc: str) -> "CLoggedLoop":
        path, flags = cref.build(workdir, cc, SOURCE)
        lib = ctypes.CDLL(str(path))
        lib.ref_closed_loop_logged.argtypes = [_P] * 4 + [_P, _I, _P, _I, _P, _I] + [_P] * 4 + [_P] * 4 + [_I] * 4 + [
            _P, _P, _I, _I, _P, _P, _I, _P]
        lib.ref_closed_loop_logged.restype = _I
        return cls(lib, flags)

    def run(self, plant, latency, records, r, u_exc, d, noise, k0, n, est_every, log_every, stats, log, row,
            watch, ring, carry) -> int:
        """Returns the next free row of ``log`` (rows, width >= 12).  ``watch``, ``ring``,
        ``carry``: the run watchdog's (:func:`kernels.watch.watch_row`)."""
        if watch.dtype != np.float64 or ring.dtype != np.uint8 or carry.dtype != np.int64 or carry.shape[0] < 6:
            raise ValueError("watch float64, ring uint8, carry int64 of 6")
        p = plant
        for a in (r, u_exc, d):
            if a.shape[0] < n:
                raise ValueError("an input is shorter than the ticks asked for")
        if noise.shape != (noise.shape[0], 2) or noise.shape[0] < n or log.shape[1] < 12:
            raise ValueError("noise must be (n, 2) and log rows 12 wide at least")
        return self.lib.ref_closed_loop_logged(
            _ptr(p.state), _ptr(p.params), _ptr(p.q), _ptr(p.mab), _ptr(p.gain), p.q.shape[0], _ptr(p.ubuf),
            p.ubuf.shape[0], _ptr(latency), latency.shape[0], *map(_ptr, records), _ptr(r), _ptr(u_exc), _ptr(d),
            _ptr(noise), k0, n, est_every, log_every, _ptr(stats), _ptr(log), log.shape[1], row, _ptr(watch),
            _ptr(ring), ring.shape[0], _ptr(carry))  # fmt: skip

"""Streaming reductions of a run log: the summary's figures and the rows the plots draw.

A run's log is read back once, in chunks of rows (:func:`servo.io.runlog.finalise_journal`
passes each chunk to its consumers), so a run of any length is summarised and plotted in
the same memory.  Each class here is one consumer: call it with every chunk (rows,
columns) in order, then read its result.
"""
from __future__ import annotations

import numpy as np

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.errors import ConfigError
from servo.run.metrics import StepResponse
from servo.scenarios import segments

COL = {c: i for i, c in enumerate(LOG_COLUMNS)}

#: The plots draw every row of a log up to this many rows; of a longer log, a min/max
#: envelope over :data:`PLOT_BUCKETS` buckets (two per pixel column of a 10-inch figure:
#: it looks the same, and drawing it costs the same for a run of any length).
PLOT_ROWS = 50_000
PLOT_BUCKETS = 2000


class PesReport:
    """The HDD benchmark's PES figures (:class:`servo.hdd.pes.PesAccumulator`) of a
    track-following run: the error ``e`` at every PES sample (every ``pes_every`` ticks,
    the samples the controller reads), the first 10 ms ignored, in tracks."""

    def __init__(self, cfg: Config):
        from servo.hdd.benchmark import benchmark
        from servo.hdd.pes import PesAccumulator

        b = benchmark(cfg.scenario.hdd_version)
        self.pes_every = max(1, int(round(cfg.run.sample_rate_hz * b.Ts)))
        if cfg.run.log_every != 1:
            raise ConfigError("config: scenario.kind = hdd_benchmark needs run.log_every = 1 (every PES sample)")
        fs_pes = cfg.run.sample_rate_hz / self.pes_every
        self.track = b.Tp
        self.acc = PesAccumulator(b.sectors, fs_pes, skip=int(round(0.01 * fs_pes)))
        need = self.acc.skip + max(2 * self.acc.spr, self.acc.nperseg)  # two revolutions, one spectrum segment
        have = cfg.n_ticks // self.pes_every
        if have < need:
            raise ConfigError(f"config: scenario.kind = hdd_benchmark needs run.duration_s >= "
                              f"{need * self.pes_every / cfg.run.sample_rate_hz:.3g} s (10 ms settling, then two "
                              f"revolutions and one spectrum segment of PES); it is {cfg.run.duration_s:g} s")  # fmt: skip

    def __call__(self, chunk: np.ndarray) -> None:
        tick, e = chunk[:, COL["tick"]], chunk[:, COL["e"]]
        self.acc.add(-e[tick % self.pes_every == 0] / self.track)  # PES = y - runout = -e, tracks

    def result(self):
        """The figures (:class:`servo.hdd.pes.PesFigures`, tracks)."""
        return self.acc.report()


class RunFigures:
    """Tracking error RMS (whole run and per scenario segment), max |error|, and each
    reference step's overshoot and settling (:class:`~servo.run.metrics.StepResponse`),
    from the ``t``, ``x``, ``r``, ``e`` columns of a run log."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.segments = segments(cfg)
        self.sum_sq = np.zeros(len(self.segments))
        self.counts = np.zeros(len(self.segments), dtype=np.int64)
        self.total_sq, self.total_n, self.max_abs = 0.0, 0, 0.0
        self.steps: list[tuple[float, StepResponse]] = []
        self._pending_steps: list[tuple[float, float, float, float]] = []  # (t_step, t_end, prev, pos) until x_hold is known
        ends = {name: b for name, _, b in self.segments}
        prev = 0.0
        s = cfg.scenario
        for i, (ts, pos) in enumerate(zip(s.step_times, s.step_positions) if s.kind == "steps" else ()):
            if ts < cfg.run.duration_s and pos != prev:
                self._pending_steps.append((ts, ends[f"step {i + 1}"], prev, pos))
            prev = pos
        self.x_hold: float | None = None

    def __call__(self, chunk: np.ndarray) -> None:
        t, x, e = chunk[:, COL["t"]], chunk[:, COL["x"]], chunk[:, COL["e"]]
        if self.x_hold is None and chunk.shape[0]:
            self.x_hold = float(chunk[0, COL["r"]])
            self.steps = [(ts, StepResponse(ts, te, self.x_hold + prev, self.x_hold + pos))
                          for ts, te, prev, pos in self._pending_steps]  # fmt: skip
        for i, (_, a, b) in enumerate(self.segments):
            m = (t >= a) & (t < b)
            self.sum_sq[i] += float(np.sum(np.square(e[m])))
            self.counts[i] += int(np.count_nonzero(m))
        self.total_sq += float(np.sum(np.square(e)))
        self.total_n += e.size
        if e.size:
            self.max_abs = max(self.max_abs, float(np.abs(e).max()))
        for _, step in self.steps:
            step.update(t, x)

    def result(self) -> dict:
        """``error_rms_m``, ``error_rms_by_segment_m``, ``error_max_m``, ``steps``."""
        rms = lambda sq, n: float(np.sqrt(sq / n)) if n else float("nan")  # noqa: E731
        return {
            "error_rms_m": rms(self.total_sq, self.total_n),
            "error_rms_by_segment_m": {name: rms(sq, n) for (name, _, _), sq, n in zip(self.segments, self.sum_sq, self.counts)},
            "error_max_m": self.max_abs,
            "steps": [{"t_s": ts, **step.result()} for ts, step in self.steps],
        }


class PlotRows:
    """The rows a run's plots draw: every row of a log of at most ``limit`` rows; of a
    longer one, ``buckets`` buckets of consecutive rows, each as two rows holding each
    column's minimum and maximum (time: the bucket's first and last), so that lines drawn
    through them trace the signal's envelope and no peak is lost."""

    def __init__(self, n_rows: int, limit: int = PLOT_ROWS, buckets: int = PLOT_BUCKETS):
        self.bucket = max(1, -(-n_rows // buckets)) if n_rows > limit else 1
        self.parts: list[np.ndarray] = []
        self._carry: np.ndarray | None = None

    def __call__(self, chunk: np.ndarray) -> None:
        if self.bucket == 1:
            self.parts.append(chunk.copy())
            return
        if self._carry is not None:
            chunk = np.concatenate([self._carry, chunk])
        whole = chunk.shape[0] - chunk.shape[0] % self.bucket
        self._carry = chunk[whole:].copy() if whole < chunk.shape[0] else None
        if whole:
            self.parts.append(self._envelope(chunk[:whole].reshape(-1, self.bucket, chunk.shape[1])))

    def _envelope(self, b: np.ndarray) -> np.ndarray:
        lo, hi = b.min(axis=1), b.max(axis=1)
        t = COL["t"]
        lo[:, t], hi[:, t] = b[:, 0, t], b[:, -1, t]
        return np.stack([lo, hi], axis=1).reshape(-1, b.shape[2])

    def rows(self) -> np.ndarray:
        parts = list(self.parts)
        if self._carry is not None:
            parts.append(self._envelope(self._carry[None]))
        return np.concatenate(parts) if parts else np.zeros((0, len(LOG_COLUMNS)))

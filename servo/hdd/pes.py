"""Position-error figures of a track-following run: 3 sigma, RRO / NRRO, spectrum, histogram.

Definitions (the NSS benchmark's ``PES_PlotTD.m`` / ``PES_FFT.m``):

* the record is cut into whole revolutions of ``spr`` samples (a trailing partial
  revolution is left out of the RRO/NRRO figures);
* RRO (the benchmark's RPE): the synchronous average, one value per sector;
  ``rro_pp = max - min`` of it;
* NRRO (NRPE): the rest; ``nrro_3sigma = 3*sqrt(mean over sectors of the per-sector
  variance across revolutions)`` (variance with ``n - 1``);
* ``sigma3``: 3 x the standard deviation of the whole record;
* spectrum: Welch, Hann window, 50 % overlap, constant detrend, one-sided PSD
  (unit^2/Hz); its cumulative 3 sigma ``3*sqrt(cumsum(psd)*df)``;
* histogram on fixed edges (values outside counted apart).

:class:`PesAccumulator` takes the record in blocks of any size and gives the same figures
as the whole record at once (sums combined exactly per sector, Welch segments cut at the
same places): a run log streamed in blocks needs no copy of the record.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal


@dataclass(frozen=True)
class PesFigures:
    """Figures of one PES record, in the record's unit (m, or tracks...).

    ``n``: samples used; ``revolutions``: whole revolutions in the RRO/NRRO figures;
    ``sigma3``, ``mean``; ``rro`` (spr,) the synchronous average; ``rro_pp``;
    ``nrro_sigma`` (spr,) per-sector NRRO standard deviation; ``nrro_3sigma``;
    ``f`` (Hz), ``psd`` (unit^2/Hz), ``cum_3sigma`` (unit) the spectrum; ``edges``,
    ``counts`` the histogram, ``outside`` (below, above) its overflow."""

    n: int
    revolutions: int
    mean: float
    sigma3: float
    rro: np.ndarray
    rro_pp: float
    nrro_sigma: np.ndarray
    nrro_3sigma: float
    f: np.ndarray
    psd: np.ndarray
    cum_3sigma: np.ndarray
    edges: np.ndarray
    counts: np.ndarray
    outside: tuple

    def summary(self, scale: float = 1.0) -> dict:
        """The scalar figures times ``scale`` (e.g. ``1/Tp`` for tracks), JSON-able."""
        return dict(n=self.n, revolutions=self.revolutions, sigma3=self.sigma3 * scale,
                    rro_pp=self.rro_pp * scale, nrro_3sigma=self.nrro_3sigma * scale)  # fmt: skip


class PesAccumulator:
    """Streaming :class:`PesFigures`: ``add(block)`` any number of times, then ``report()``.

    ``spr``: samples per revolution; ``fs``: PES sample rate (Hz); ``skip``: leading
    samples to ignore (the benchmark ignores 10 ms); ``nperseg``: Welch segment length
    (default: ``8*spr``); ``edges``: histogram bin edges (default: 201 edges over
    +-``hist_range``); ``hist_range``: default half-range of the histogram, or None to take
    8 sigma of the first whole revolution seen.
    """

    def __init__(self, spr: int, fs: float, skip: int = 0, nperseg: int | None = None, edges=None,
                 hist_range: float | None = None):  # fmt: skip
        if spr < 2 or fs <= 0 or skip < 0:
            raise ValueError("need spr >= 2, fs > 0, skip >= 0")
        self.spr, self.fs, self.skip = int(spr), float(fs), int(skip)
        self.nperseg = int(nperseg or 8 * spr)
        self.step = self.nperseg // 2
        self.window = signal.get_window("hann", self.nperseg)
        self.edges = None if edges is None else np.asarray(edges, float)
        self.hist_range = hist_range
        self.seen = 0  # samples offered, skip included
        self.n = 0
        self.total = 0.0
        self.total_m2 = 0.0  # about the running mean (Chan et al.)
        self.rev_buf = np.zeros(0)
        self.revs = 0
        self.sec_mean = np.zeros(self.spr)
        self.sec_m2 = np.zeros(self.spr)
        self.seg_buf = np.zeros(0)
        self.segments = 0
        self.psd_sum = np.zeros(self.nperseg // 2 + 1)
        self.counts = None
        self.below = self.above = 0

    @staticmethod
    def _combine(n_a, mean_a, m2_a, n_b, mean_b, m2_b):
        n = n_a + n_b
        delta = mean_b - mean_a
        return n, mean_a + delta * (n_b / n), m2_a + m2_b + delta * delta * (n_a * n_b / n)

    def add(self, block) -> None:
        """Add the next samples (1-D, finite)."""
        x = np.asarray(block, dtype=float).ravel()
        if not np.all(np.isfinite(x)):
            raise ValueError("PES block holds non-finite values")
        cut = min(max(self.skip - self.seen, 0), x.shape[0])
        self.seen += x.shape[0]
        x = x[cut:]
        if x.shape[0] == 0:
            return
        # whole record: mean and M2
        mean = self.total / self.n if self.n else 0.0
        self.n, mean, self.total_m2 = self._combine(self.n, mean, self.total_m2, x.shape[0], x.mean(),
                                                    float(np.sum((x - x.mean()) ** 2)))  # fmt: skip
        self.total = mean * self.n
        # whole revolutions: per-sector mean and M2 across revolutions
        buf = np.concatenate([self.rev_buf, x])
        k = buf.shape[0] // self.spr
        if k:
            revs = buf[: k * self.spr].reshape(k, self.spr)
            if self.counts is None:
                self._init_hist(revs[0])
            bm = revs.mean(axis=0)
            bm2 = np.sum((revs - bm) ** 2, axis=0)
            n_a = self.revs
            n = n_a + k
            delta = bm - self.sec_mean
            self.sec_mean = self.sec_mean + delta * (k / n)
            self.sec_m2 = self.sec_m2 + bm2 + delta * delta * (n_a * k / n)
            self.revs = n
        self.rev_buf = buf[k * self.spr :]
        # Welch segments at 0, step, 2*step, ... of the record after skip
        seg = np.concatenate([self.seg_buf, x])
        i = 0
        while i + self.nperseg <= seg.shape[0]:
            s = seg[i : i + self.nperseg]
            _, p = signal.periodogram(s - s.mean(), self.fs, window=self.window, detrend=False, scaling="density")
            self.psd_sum += p
            self.segments += 1
            i += self.step
        self.seg_buf = seg[i:]
        # histogram
        if self.counts is None and self.edges is not None:
            self._init_hist(None)
        if self.counts is not None:
            self._hist(x)
        else:
            self._pending = np.concatenate([getattr(self, "_pending", np.zeros(0)), x])

    def _init_hist(self, first_rev):
        if self.edges is None:
            r = self.hist_range if self.hist_range is not None else 8 * float(np.std(first_rev)) or 1.0
            self.edges = np.linspace(-r, r, 201)
        self.counts = np.zeros(self.edges.shape[0] - 1, dtype=np.int64)
        pending = getattr(self, "_pending", None)
        if pending is not None and pending.shape[0]:
            self._hist(pending)
        self._pending = np.zeros(0)

    def _hist(self, x):
        self.counts += np.histogram(x, self.edges)[0]
        self.below += int(np.sum(x < self.edges[0]))
        self.above += int(np.sum(x > self.edges[-1]))

    def report(self) -> PesFigures:
        """The figures of everything added so far (needs one whole revolution and one
        Welch segment)."""
        if self.revs < 2:
            raise ValueError(f"PES record too short: {self.revs} whole revolutions of {self.spr} samples (need 2)")
        if self.segments < 1:
            raise ValueError(f"PES record too short for one spectrum segment of {self.nperseg} samples")
        if self.counts is None:
            self._init_hist(None)
        rro = self.sec_mean.copy()
        nrro_sigma = np.sqrt(self.sec_m2 / (self.revs - 1))
        psd = self.psd_sum / self.segments
        df = self.fs / self.nperseg
        f = np.arange(psd.shape[0]) * df
        return PesFigures(
            n=self.n, revolutions=self.revs, mean=self.total / self.n,
            sigma3=3 * float(np.sqrt(self.total_m2 / self.n)), rro=rro, rro_pp=float(rro.max() - rro.min()),
            nrro_sigma=nrro_sigma, nrro_3sigma=3 * float(np.sqrt(np.mean(nrro_sigma**2))),
            f=f, psd=psd, cum_3sigma=3 * np.sqrt(np.cumsum(psd) * df), edges=self.edges.copy(),
            counts=self.counts.copy(), outside=(self.below, self.above),
        )  # fmt: skip


def pes_figures(e, spr: int, fs: float, skip: int = 0, **kw) -> PesFigures:
    """:class:`PesFigures` of a whole record ``e`` (1-D): one block through :class:`PesAccumulator`."""
    acc = PesAccumulator(spr, fs, skip, **kw)
    acc.add(e)
    return acc.report()

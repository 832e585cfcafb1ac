"""A discrete track-following controller: two cascades of second-order sections at two rates.

:class:`Design` is the contract between the design tools (:mod:`servo.design`) and a
controller that runs it: ``slow_sos`` runs every ``pes_every`` ticks on the position error
``e`` (m) and gives a current (A); its output is held between PES samples; ``fast_sos``
runs every tick on that held value (notches, low-pass) and gives the command (A).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from servo.design import sections


@dataclass(frozen=True)
class Design:
    """A two-rate controller ``e (m) -> u (A)``.

    ``slow_sos`` (n, 6), ``fast_sos`` (m, 6): float64 cascades (``b0 b1 b2 a0 a1 a2``,
    ``a0 = 1``, at most :data:`~servo.design.sections.MAX_SECTIONS` each); ``fs``: tick
    rate (Hz); ``pes_every``: ticks per PES sample (1 or 2), so ``slow_sos`` runs at
    ``fs / pes_every``; ``integrators``: poles at ``z = 1`` the slow cascade may hold (a
    PID's integrator); ``blocks``: the continuous description it was discretised from
    (:class:`~servo.design.analog.Block` list, empty when the design is discrete from the
    start); ``method``: the discretisation; ``info``: free-form facts for documentation.

    Construction checks both cascades (:func:`servo.design.sections.check`) and raises
    ValueError when one is too long, not finite or has an unstable section.
    """

    slow_sos: np.ndarray
    fast_sos: np.ndarray
    fs: float
    pes_every: int = 1
    integrators: int = 0
    blocks: tuple = ()
    method: str = ""
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.pes_every not in (1, 2):
            raise ValueError(f"pes_every = {self.pes_every}: 1 or 2")
        if not (np.isfinite(self.fs) and self.fs > 0):
            raise ValueError(f"fs = {self.fs}: a positive sample rate in Hz")
        object.__setattr__(self, "slow_sos", sections.check(self.slow_sos, "slow cascade", self.integrators))
        object.__setattr__(self, "fast_sos", sections.check(self.fast_sos, "fast cascade", 0))
        object.__setattr__(self, "fs", float(self.fs))

    @property
    def fs_pes(self) -> float:
        """PES sample rate (Hz), the slow cascade's rate."""
        return self.fs / self.pes_every

    def slow_response(self, f_hz) -> np.ndarray:
        """Slow cascade alone at ``f_hz`` (A/m), at rate :attr:`fs_pes`."""
        return sections.response(self.slow_sos, f_hz, self.fs_pes)

    def fast_response(self, f_hz) -> np.ndarray:
        """Fast cascade alone at ``f_hz`` (A/A), at rate :attr:`fs`."""
        return sections.response(self.fast_sos, f_hz, self.fs)

    def hold_response(self, f_hz) -> np.ndarray:
        """The hold between the rates, ``(1/N) * sum_{k<N} exp(-j*2*pi*f*k/fs)``, ``N = pes_every``."""
        f = np.asarray(f_hz, dtype=float)
        n = self.pes_every
        return sum(np.exp(-2j * np.pi * f * k / self.fs) for k in range(n)) / n

    def response(self, f_hz) -> np.ndarray:
        """Frequency response ``e -> u`` (A/m) at ``f_hz`` (Hz, any shape, below ``fs_pes/2``).

        ``slow(f) * hold(f) * fast(f)``.  With ``pes_every = 1`` this is exact.  With 2 the
        controller is periodically time-varying: a sinusoid at ``f`` sampled at the PES rate
        comes out of the hold as the sinusoid at ``f`` (the value returned: the hold keeps
        ``hold(f)``, a half-tick delay and a ``cos(pi*f/fs)`` roll-off, of it) plus images at
        ``fs_pes - f``, ``fs_pes + f``, ... which this neglects; the fast cascade then filters
        both.  The exact loop at the PES rate, images included, is
        :func:`servo.design.loop.open_loop`.
        """
        return self.slow_response(f_hz) * self.hold_response(f_hz) * self.fast_response(f_hz)

    def continuous_response(self, f_hz) -> np.ndarray:
        """The continuous prototype's response at ``f_hz`` (A/m); NaN when there is none."""
        f = np.asarray(f_hz, dtype=float)
        if not self.blocks:
            return np.full(f.shape, np.nan + 0j)
        h = np.ones(f.shape, complex)
        for b in self.blocks:
            h *= b.response(f)
        return h

    def describe(self) -> dict:
        """Plain-data description (JSON-able): rates, method, blocks with their parameters, sections."""
        return dict(
            fs=self.fs, pes_every=self.pes_every, fs_pes=self.fs_pes, method=self.method,
            blocks=[dict(name=b.name, rate=b.rate, **b.params) for b in self.blocks],
            slow_sos=self.slow_sos.tolist(), fast_sos=self.fast_sos.tolist(), **self.info,
        )  # fmt: skip

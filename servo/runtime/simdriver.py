"""``SimDriver``: the simulated VCM drive behind the driver interface.

Each ``write`` advances the plant one sample (:func:`kernels.plant.plant_step`), each
``read`` samples its sensor (:func:`kernels.plant.plant_measure`).  Time is the tick
counter.  Sensor noise is drawn from ``numpy.random.default_rng(seed)`` in blocks of
:data:`NOISE_BLOCK` ticks (two standard normals per tick: position, velocity), so a
given seed gives the same noise whether the run goes tick by tick or in compiled blocks.

The link's command latency ``d`` is modelled here like on the board: the command of tick
k enters the plant at tick k+d; with the loop on the board (``link.loop = "board"``) the
command does not cross the link, and ``d`` is 0.  The drive starts at rest, held at its initial position
by the holding current (as if handed over by a previous controller); its safe state is
zero current.
"""
from __future__ import annotations

import math

import numpy as np

from kernels.delay import shift_in
from kernels._cache import entry_point
from kernels.plant import plant_measure, plant_step
from servo.config import Config
from servo.errors import DriverError
from servo.runtime.driver import Driver, DriverInfo
from servo.runtime.window import BLOCK, Window
from servo.scenarios import Inputs
from servo.runtime.simplant import SimPlant, build_plant

NOISE_BLOCK = BLOCK  # ticks; drawing a block takes ~25 us, small enough not to upset a paced tick


class SimDriver(Driver):
    """Driver for the simulated drive of ``cfg.drive`` at ``cfg.run.sample_rate_hz``.

    ``inputs``: the run's inputs, of which the drive applies the disturbance force (A)
    at each tick (:meth:`~servo.scenarios.base.Inputs.disturbance`); None: no force.
    """

    def __init__(self, cfg: Config, inputs: Inputs | None = None):
        super().__init__()
        self.cfg = cfg
        self.tick = 0
        self._d = Window((inputs or Inputs()).disturbance)
        self.plant: SimPlant | None = None
        self.latency = np.zeros(0)

    # ---- lifecycle ---------------------------------------------------------------------
    def _on_configure(self) -> DriverInfo:
        cfg = self.cfg
        self.plant = build_plant(cfg.drive, cfg.dt)
        self.latency = np.full(cfg.link.loop_latency_ticks, self.plant.u_hold)
        self._x = self.plant.state.view(np.float64)  # [x, v, H]: a float view for the finiteness check
        self._rng = np.random.default_rng(cfg.run.seed)
        self._noise = np.empty((NOISE_BLOCK, 2))
        self._noise_block = -1
        self._warm_up()
        return DriverInfo(
            name="sim",
            sample_rate_hz=cfg.run.sample_rate_hz,
            has_velocity=cfg.drive.measures_velocity,
            command_latency_ticks=cfg.link.loop_latency_ticks,
            current_limit=cfg.drive.current_limit,
        )

    def _warm_up(self) -> None:
        """Call the plant kernels once on scratch copies: any first-call cost is paid
        here, not in the loop (their signatures are explicit, so import compiled them).
        Also draw the first noise block (~0.2 ms), which the first tick would otherwise
        pay; the draws are the same, only earlier."""
        p = self.plant
        ps, q, ub = p.state.copy(), p.q.copy(), p.ubuf.copy()
        # the kernels without per-call dispatch, checked on these copies of the plant's arrays
        self._measure = entry_point(plant_measure, ps, p.params, q, p.gain, 0.0, 0.0)
        self._step = entry_point(plant_step, ps, p.params, q, p.mab, ub, p.u_hold, 0.0)
        shift_in(self.latency.copy(), 0.0)
        self.noise(0, 1)
        self._d.load(0)  # the first window of the disturbance, likewise

    def _read(self) -> tuple[float, float]:
        k = self.tick
        noise = self.noise(k, 1)
        p = self.plant
        self.check_state()  # (a fault here: the base class puts the drive in its safe state)
        return self._measure(p.state, p.params, p.q, p.gain, noise[0, 0], noise[0, 1])

    def _write(self, u: float) -> None:
        p = self.plant
        u_in = shift_in(self.latency, u)
        self._step(p.state, p.params, p.q, p.mab, p.ubuf, u_in, self.disturbance_at(self.tick))
        self.tick += 1

    def _on_deactivate(self) -> None:
        # amplifier off: nothing in flight on the link or in the input delay
        self.latency[:] = 0.0
        self.plant.ubuf[:] = 0.0

    @property
    def applied_current(self) -> float:
        """The command (A) that entered the amplifier last (after the link latency)."""
        return 0.0 if self.plant is None else float(self.plant.ubuf[0])

    def check_state(self) -> None:
        """Raise :class:`~servo.errors.DriverError` if the plant's position is no longer
        finite (the simulation diverged).  Checked on the state, not on a sample: the
        sensor's quantiser casts NaN to a finite integer.  The tick path checks before
        every sample, the fast path after every block of ticks."""
        if not math.isfinite(self._x[0]):
            raise DriverError(f"simulated drive: the position is not finite at tick {self.tick}: the simulation "
                              "diverged (an unstable loop or extreme [drive] values); drive set to zero current")

    # ---- inputs, shared with the compiled fast path --------------------------------------
    def noise(self, k0: int, n: int) -> np.ndarray:
        """Standard-normal draws (n, 2) of ticks ``k0 .. k0+n-1``, all in one noise block.
        Blocks are generated in order; asking for an earlier block is an error."""
        j = k0 // NOISE_BLOCK
        if (k0 + n - 1) // NOISE_BLOCK != j:
            raise ValueError("noise request spans two blocks")
        while self._noise_block < j:
            self._rng.standard_normal(out=self._noise)
            self._noise_block += 1
        if self._noise_block != j:
            raise ValueError("noise block already consumed")
        i = k0 - j * NOISE_BLOCK
        return self._noise[i : i + n]

    def disturbance_at(self, k: int) -> float:
        """The disturbance force (A) of tick ``k``."""
        return self._d.at(k)

    def disturbance(self, k0: int, n: int) -> np.ndarray:
        """The disturbance (A) of ticks ``k0 .. k0+n-1``, all in one input block (a view)."""
        i = self._d.load(k0)
        if i + n > self._d.size:
            raise ValueError("disturbance request spans two blocks")
        return self._d.values[i : i + n]

"""The driver interface: one lifecycle for the simulated drive and for a serial board.

Modelled on ros2_control's hardware interface::

    UNCONFIGURED --configure()--> INACTIVE --activate()--> ACTIVE
         ACTIVE --deactivate()--> INACTIVE --close()--> CLOSED
    read() in INACTIVE or ACTIVE; write(u) in ACTIVE only.

* ``configure`` opens the device, checks versions, and warms up every kernel so that
  nothing compiles inside the loop.  Returns :class:`DriverInfo`.
* ``activate`` allows commands.
* ``read`` returns sample k: ``(x, v)`` in m and m/s (``v`` NaN without a velocity sensor).
* ``write(u)`` sends the current command (A) for tick k; the drive applies it after the
  link's latency.  A non-finite command is refused: the drive goes to its safe state.
* ``deactivate`` puts the drive in its **safe state: zero current**.
* ``close`` releases the device (deactivating first if needed).
* ``report`` returns what the run summary records about the drive or its link (a dict,
  or None when there is nothing to report: the default).

A driver whose drive runs the controller itself (a board with the loop on it,
:class:`hil.onboard.OnBoardDriver`) sets :attr:`Driver.closes_loop` and implements
:meth:`Driver.run_loop`; :func:`servo.runtime.loop.run_closed_loop` then hands it the run
(it activates the drive itself, after sending the controller).

The base class owns the state machine; subclasses implement the ``_on_*`` hooks.  The safe
state cannot be skipped: ``close`` deactivates, the context manager closes on every exit
path (exceptions and Ctrl-C included), and any exception escaping ``read``/``write``
deactivates before it propagates.
"""
from __future__ import annotations

import enum
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

from servo.errors import DriverError, LifecycleError


class DriverState(enum.Enum):
    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"
    ACTIVE = "active"
    CLOSED = "closed"


@dataclass(frozen=True)
class DriverInfo:
    """What a configured driver reports about the drive behind it."""

    name: str
    sample_rate_hz: float
    has_velocity: bool
    command_latency_ticks: int
    current_limit: float  # A


class Driver(ABC):
    """Base class of every driver; see the module doc for the lifecycle."""

    closes_loop: bool = False
    """True: the drive runs the controller itself (:meth:`run_loop`), the host supervises."""

    def __init__(self) -> None:
        self.state = DriverState.UNCONFIGURED
        self.info: DriverInfo | None = None

    # ---- lifecycle (public, final) ---------------------------------------------------
    def configure(self) -> DriverInfo:
        self._require(DriverState.UNCONFIGURED, "configure")
        try:
            self.info = self._on_configure()
        except BaseException:
            self._on_close()
            self.state = DriverState.CLOSED
            raise
        self.state = DriverState.INACTIVE
        return self.info

    def activate(self) -> None:
        self._require(DriverState.INACTIVE, "activate")
        self._on_activate()
        self.state = DriverState.ACTIVE

    def read(self) -> tuple[float, float]:
        if self.state not in (DriverState.INACTIVE, DriverState.ACTIVE):
            raise LifecycleError(f"driver: read() while {self.state.value}")
        try:
            return self._read()
        except BaseException:
            self.deactivate()
            raise

    def write(self, u: float) -> None:
        self._require(DriverState.ACTIVE, "write")
        if not math.isfinite(u):
            self.deactivate()
            raise DriverError(f"driver: refused a non-finite current command ({u!r}); drive set to zero current")
        try:
            self._write(u)
        except BaseException:
            self.deactivate()
            raise

    def deactivate(self) -> None:
        """Safe state (zero current).  Idempotent; a no-op unless ACTIVE."""
        if self.state is DriverState.ACTIVE:
            self.state = DriverState.INACTIVE
            self._on_deactivate()

    def close(self) -> None:
        """Deactivate if needed, then release the device.  Idempotent."""
        if self.state is DriverState.CLOSED:
            return
        try:
            self.deactivate()
        finally:
            self.state = DriverState.CLOSED
            self._on_close()

    def __enter__(self) -> "Driver":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _require(self, state: DriverState, what: str) -> None:
        if self.state is not state:
            raise LifecycleError(f"driver: {what}() needs state {state.value}, not {self.state.value}")

    # ---- what a driver implements ------------------------------------------------------
    @property
    @abstractmethod
    def applied_current(self) -> float:
        """The current (A) the drive applies now (for a bumpless hand-over)."""

    @abstractmethod
    def _on_configure(self) -> DriverInfo: ...

    def _on_activate(self) -> None:
        pass

    @abstractmethod
    def _read(self) -> tuple[float, float]: ...

    @abstractmethod
    def _write(self, u: float) -> None: ...

    @abstractmethod
    def _on_deactivate(self) -> None:
        """Command zero current.  Must not raise on a dead link: best effort, then return."""

    def _on_close(self) -> None:
        pass

    def run_loop(self, cfg, controller, inputs, log, stats, watchdog) -> None:
        """Run the whole loop on the drive (a driver with :attr:`closes_loop` only): start
        ``controller`` bumplessly, activate, run ``cfg.n_ticks`` ticks with the reference
        and excitation of ``inputs``; the rows go to ``log``, the tracking error to
        ``stats`` (:func:`kernels.compose.error_stats`), ``watchdog`` looks at the rows."""
        raise NotImplementedError(f"{type(self).__name__} does not run the loop itself")

    def report(self) -> dict | None:
        """What the run summary records about the drive/link; None for a drive with
        nothing to report."""
        return None

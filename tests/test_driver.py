"""Driver lifecycle and the safe state on every exit path."""
import math

import numpy as np
import pytest

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.errors import DriverError, LifecycleError
from servo.io.runlog import RunLog
from servo.runtime.controller import Controller
from servo.runtime.driver import DriverState
from servo.runtime.loop import run_closed_loop
from servo.scenarios import scenario_inputs
from servo.runtime.simdriver import SimDriver


def test_lifecycle_order_is_enforced():
    drv = SimDriver(Config())
    with pytest.raises(LifecycleError):
        drv.read()
    with pytest.raises(LifecycleError):
        drv.activate()
    info = drv.configure()
    assert info.sample_rate_hz == 50_000 and info.has_velocity
    with pytest.raises(LifecycleError):
        drv.write(0.0)  # not active yet
    drv.read()  # reading while inactive is allowed
    drv.activate()
    drv.write(drv.applied_current)
    drv.deactivate()
    drv.deactivate()  # idempotent
    assert drv.applied_current == 0.0
    with pytest.raises(LifecycleError):
        drv.write(0.0)
    drv.close()
    drv.close()
    assert drv.state is DriverState.CLOSED


def test_close_and_context_exit_deactivate():
    with SimDriver(Config()) as drv:
        drv.configure()
        drv.activate()
        drv.write(0.05)
        drv.write(0.05)
        assert drv.applied_current == 0.05
    assert drv.state is DriverState.CLOSED
    assert drv.applied_current == 0.0


def test_non_finite_command_is_refused_and_drive_goes_safe():
    with SimDriver(Config()) as drv:
        drv.configure()
        drv.activate()
        with pytest.raises(DriverError, match="non-finite"):
            drv.write(math.nan)
        assert drv.state is DriverState.INACTIVE
        assert drv.applied_current == 0.0


class ExplodingController(Controller):
    """Fails at a given tick, as a bug in a user's controller would."""

    def __init__(self, cfg, at):
        super().__init__(cfg)
        self.n, self.at = 0, at

    def tick(self, x, v, r, u_exc):
        self.n += 1
        if self.n == self.at:
            raise RuntimeError("boom")
        return super().tick(x, v, r, u_exc)


def test_exception_inside_the_loop_leaves_zero_current_and_the_log_on_disk(tmp_path):
    cfg = Config().replace(run={"duration_s": 0.5})
    inputs = scenario_inputs(cfg)
    drv = SimDriver(cfg, inputs)
    fail_at = 20_001
    with pytest.raises(RuntimeError, match="boom"):
        with drv, RunLog(tmp_path, "log", LOG_COLUMNS, block_rows=4096) as log:
            run_closed_loop(cfg, drv, ExplodingController(cfg, fail_at), inputs, log)
    assert drv.state is DriverState.CLOSED and drv.applied_current == 0.0
    assert drv.tick == fail_at - 1  # no command was written after the failure
    data = np.load(tmp_path / "log.npz")
    assert data["tick"].shape == (fail_at - 1,)  # every tick before the failure, not just full blocks
    np.testing.assert_array_equal(data["tick"], np.arange(fail_at - 1))
    assert not (tmp_path / "log.journal").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "log.npz"]  # nothing half-written


def test_keyboard_interrupt_also_ends_in_the_safe_state(tmp_path):
    cfg = Config().replace(run={"duration_s": 0.1})

    class CtrlC(ExplodingController):
        def tick(self, x, v, r, u_exc):
            if self.n == 100:
                raise KeyboardInterrupt
            return super().tick(x, v, r, u_exc)

    drv = SimDriver(cfg)
    with pytest.raises(KeyboardInterrupt):
        with drv, RunLog(tmp_path, "log", LOG_COLUMNS) as log:
            run_closed_loop(cfg, drv, CtrlC(cfg, 10**9), scenario_inputs(cfg), log)
    assert drv.applied_current == 0.0 and drv.state is DriverState.CLOSED
    assert np.load(tmp_path / "log.npz")["tick"].shape == (100,)


def test_a_simulation_that_diverges_is_a_fault_with_the_drive_safe_and_the_log_kept(tmp_path):
    """Issue 9.5: a non-finite plant state ran on and was summarised as a result."""
    import math

    from kernels.compose import LOG_COLUMNS
    from servo.config import Config
    from servo.errors import DriverError
    from servo.io.runlog import RunLog
    from servo.runtime.controller import Controller
    from servo.runtime.loop import CALL_TICKS, run_closed_loop
    from servo.scenarios import scenario_inputs
    from servo.runtime.simdriver import NOISE_BLOCK, SimDriver

    cfg = Config().replace(run={"duration_s": 0.1})
    for fast in (False, True):
        drv = SimDriver(cfg)
        drv.configure()
        real_at, real_block = drv.disturbance_at, drv.disturbance

        # the plant diverges from the second noise block on: a non-finite force enters it
        # (through the inputs, which the fast path computes a block ahead in a thread of
        # its own, so the state itself is not touched from outside the loop)
        def disturbance_at(k):
            return math.nan if k >= NOISE_BLOCK else real_at(k)

        def disturbance(k0, n):
            d = real_block(k0, n).copy()
            d[max(0, NOISE_BLOCK - k0) :] = math.nan
            return d

        drv.disturbance_at, drv.disturbance = disturbance_at, disturbance
        with pytest.raises(DriverError, match="the simulation diverged") as err:
            with RunLog(tmp_path, f"log{int(fast)}", LOG_COLUMNS) as log:
                run_closed_loop(cfg, drv, Controller(cfg), scenario_inputs(cfg), log, fast=fast)
        assert "\n" not in str(err.value)
        assert drv.applied_current == 0.0 and drv.latency.sum() == 0.0  # safe state
        rows = np.load(log.npz_path)["tick"].shape[0]
        # every tick before the fault is kept, on disk; the run stops within the block (tick
        # path) or the compiled call (fast path, servo.runtime.loop.CALL_TICKS) it diverged in
        assert NOISE_BLOCK <= rows <= (NOISE_BLOCK + CALL_TICKS if fast else 2 * NOISE_BLOCK)

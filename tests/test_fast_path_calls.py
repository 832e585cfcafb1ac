"""The fast path's compiled calls (``servo.runtime.loop``): up to ``CALL_TICKS`` ticks a
call, each ending where the run log's block is full, so that a block is never overrun
and the watchdog sees every row before its block is handed over; the log is the tick
path's, to the bit, whatever the block size and the logging rate."""
import types

import numpy as np
import pytest

from kernels.compose import LOG_COLUMNS
from servo.config import Config
from servo.errors import UnstableLoop
from servo.io.runlog import RunLog
from servo.runtime import loop
from servo.runtime.controller import Controller
from servo.runtime.loop import CALL_TICKS, run_closed_loop
from servo.runtime.simdriver import SimDriver
from servo.runtime.watchdog import Watchdog
from servo.runtime.window import BLOCK
from servo.scenarios import scenario_inputs


def _run(cfg, fast, tmp_path, name, block_rows):
    inputs = scenario_inputs(cfg)
    # no headroom: a call that wrote past the block would write past the buffer
    with SimDriver(cfg, inputs) as drv, RunLog(tmp_path, name, LOG_COLUMNS, block_rows=block_rows, headroom=0) as log:
        calls = []
        flush = log.maybe_flush

        def seen():  # the rows at each look, before the block may be handed over
            calls.append(log.rows)
            flush()

        log.maybe_flush = seen
        res = run_closed_loop(cfg, drv, Controller(cfg), inputs, log, fast=fast, timing=False)
        return log.recorded().copy(), res.stats.copy(), calls


@pytest.mark.parametrize("log_every, block_rows", [(1, 8192), (1, 3000), (3, 1000), (7, 5000)])
def test_calls_end_at_the_log_block_and_log_the_tick_paths_bits(tmp_path, log_every, block_rows):
    cfg = Config().replace(run={"duration_s": 0.5, "log_every": log_every})  # 25 000 ticks: several chunks
    fast_rows, fast_stats, looks = _run(cfg, True, tmp_path, "f", block_rows)
    tick_rows, tick_stats, _ = _run(cfg, False, tmp_path, "t", block_rows)
    assert fast_rows.shape[0] == -(-cfg.n_ticks // log_every)
    assert fast_rows.tobytes() == tick_rows.tobytes() and fast_stats.tobytes() == tick_stats.tobytes()
    assert max(looks) <= block_rows  # never past the block
    assert looks.count(block_rows) == fast_rows.shape[0] // block_rows  # every full block looked at, then handed over
    # one call per chunk of inputs unless the block ends inside it: far fewer calls than input blocks
    assert len(looks) <= -(-cfg.n_ticks // CALL_TICKS) + fast_rows.shape[0] // block_rows + 1


def test_the_input_chunks_tile_the_run_on_the_call_grid():
    cfg = Config().replace(run={"duration_s": 0.5})
    inputs = scenario_inputs(cfg)
    drv = SimDriver(cfg, inputs)
    drv.configure()
    chunks = [(k, m) for k, m, *_ in loop._fast_inputs(cfg, drv, inputs, 0, cfg.n_ticks)]
    assert chunks[0] == (0, BLOCK)  # the first is one block: the loop starts as soon as it is drawn
    assert all(k % CALL_TICKS == 0 for k, _ in chunks[1:-1] if k >= CALL_TICKS)
    assert [k for k, _ in chunks] == list(np.cumsum([0] + [m for _, m in chunks[:-1]]))
    assert sum(m for _, m in chunks) == cfg.n_ticks and max(m for _, m in chunks) <= CALL_TICKS


def _verdict(cfg, fast, tmp_path, name):
    """The run's UnstableLoop message and the rows it recorded."""
    inputs = scenario_inputs(cfg)
    with SimDriver(cfg, inputs) as drv, RunLog(tmp_path, name, LOG_COLUMNS, block_rows=3000) as log:
        with pytest.raises(UnstableLoop) as err:
            run_closed_loop(cfg, drv, Controller(cfg), inputs, log, fast=fast, timing=False)
        return str(err.value), log.recorded().copy()


@pytest.mark.parametrize("run, limit", [
    ({"fault_position": 1.5e-5}, 1.0),  # the scenario's 20 um step leaves it
    ({"fault_limit_share": 0.2, "fault_window_s": 0.01}, 2.5e-3),  # |u| at 2.5 mA on 20 % of a 10 ms window
])  # fmt: skip
def test_the_loops_tests_of_each_row_give_the_watchdogs_verdict(tmp_path, run, limit):
    """The compiled loop tests each row as it logs it (kernels.watch.watch_row); its
    verdict is the one the watchdog's scan gives over the same rows, and the tick path's
    (which looks every 256 rows: only the end of the window it names may differ)."""
    cfg = Config().replace(run={"duration_s": 0.5, **run}, controller={"current_limit": limit})
    fast, rows = _verdict(cfg, True, tmp_path, "f")
    scan = Watchdog(cfg)
    with pytest.raises(UnstableLoop) as err:
        scan.look(types.SimpleNamespace(data=np.ascontiguousarray(rows), rows=rows.shape[0]))
    assert fast == str(err.value)
    tick, _ = _verdict(cfg, False, tmp_path, "t")
    assert fast.split(" near t")[0] == tick.split(" near t")[0]
    assert ("position reached" in fast) == ("fault_position" in run)

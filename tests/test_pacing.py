"""Real-time pacing: absolute deadlines, lateness, overrun policy, GC kept out."""
import gc
import time

import pytest

from servo.pacing import OverrunFault, Pacer, realtime_section


def test_absolute_deadlines_do_not_drift():
    period, n = 200e-6, 2000
    p = Pacer(period, n)
    p.start()
    for k in range(n):
        p.wait(k)
        if k % 100 == 0:
            time.sleep(150e-6)  # an occasional long tick: later ticks catch up, no drift
    elapsed = (time.perf_counter_ns() - p.t0) / 1e9
    assert elapsed == pytest.approx((n - 1) * period, abs=5e-3)
    r = p.report()
    assert r["ticks"] == n and r["lateness_us_p50"] < 100


def test_overruns_are_counted_and_can_fault():
    p = Pacer(100e-6, 100)
    p.start()
    for k in range(10):
        p.wait(k)
        time.sleep(300e-6)  # every tick runs over
    assert p.overruns >= 8
    f = Pacer(100e-6, 100, policy="fault", max_consecutive=3)
    f.start()
    with pytest.raises(OverrunFault, match="3 consecutive deadline overruns"):
        for k in range(10):
            f.wait(k)
            time.sleep(300e-6)


def test_realtime_section_freezes_gc_and_restores():
    assert gc.isenabled()
    with realtime_section(lock_memory=False) as grant:
        assert grant.gc_frozen and not gc.isenabled()
    assert gc.isenabled()

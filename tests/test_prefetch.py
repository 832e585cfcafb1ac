"""The fast path's input thread: items in order, the generator's error at its item, and a
consumer that stops early stops the thread."""
import threading

import pytest

from servo.runtime.prefetch import Prefetch


def test_items_in_order_then_the_generators_error():
    def gen():
        yield from range(5)
        raise ValueError("noise request spans two blocks")

    seen = []
    with pytest.raises(ValueError, match="spans two blocks"), Prefetch(gen()) as items:
        for x in items:
            seen.append(x)
    assert seen == [0, 1, 2, 3, 4]


def test_a_consumer_that_stops_early_stops_the_thread():
    made = []

    def gen():
        for i in range(10**6):
            made.append(i)
            yield i

    p = Prefetch(gen(), ahead=2)
    assert next(p) == 0
    p.close()
    assert not any(t.name == "fast-path-inputs" and t.is_alive() for t in threading.enumerate())
    assert len(made) <= 5  # at most the items queued ahead, not the whole generator

"""Blocks of a generator computed ahead, in a thread of their own.

The compiled fast path runs a chunk of ticks per call with the interpreter lock released;
the inputs of the next chunk (the scenario's windows, the disturbance, the sensor
noise: NumPy work that releases the lock too) are computed meanwhile by a
:class:`Prefetch` thread, in the order the loop consumes them, so a run computes the
same numbers as when it drew them itself, and its own thread does not pay them.

The hand-over is two :class:`queue.SimpleQueue` (implemented in C): the items, and the
room for them (``ahead`` tokens), so that taking an item costs the consumer's thread a
fraction of a microsecond when it is ready, where :class:`queue.Queue` (a condition
variable in Python) cost it several.
"""
from __future__ import annotations

import queue
import threading
from typing import Iterator


class Prefetch:
    """Iterate ``items`` (a generator) in a daemon thread, at most ``ahead`` items ahead of
    the consumer.  An exception in the generator is raised to the consumer at the item
    where it happened; :meth:`close` (or leaving the ``with`` block) stops the thread."""

    _END = object()

    def __init__(self, items: Iterator, ahead: int = 2):
        self._items = items
        self._ready: queue.SimpleQueue = queue.SimpleQueue()
        self._room: queue.SimpleQueue = queue.SimpleQueue()  # one token per item the producer may still queue
        for _ in range(max(1, int(ahead))):
            self._room.put(None)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fast-path-inputs", daemon=True)
        self._thread.start()

    def _put(self, item) -> bool:
        while not self._stop.is_set():
            try:
                self._room.get(timeout=0.05)
            except queue.Empty:
                continue
            self._ready.put(item)
            return True
        return False

    def _run(self) -> None:
        try:
            for item in self._items:
                if not self._put((item, None)):
                    return
        except BaseException as exc:  # handed to the consumer
            self._put((None, exc))
            return
        self._put((self._END, None))

    def __iter__(self):
        return self

    def __next__(self):
        item, exc = self._ready.get()
        self._room.put(None)
        if exc is not None:
            raise exc
        if item is self._END:
            raise StopIteration
        return item

    def close(self) -> None:
        self._stop.set()
        self._thread.join()

    def __enter__(self) -> "Prefetch":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

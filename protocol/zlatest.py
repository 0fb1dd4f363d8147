"""The newest-sample-only subscriber the real-time controller receives states with (`LatestSubscriber`).

zenoh runs the subscriber's callback in its own receiving thread (`Callback(..., indirect=False)`), and the callback
is `queue.SimpleQueue.put`, C code: no Python frame runs for an arrival, and the consumer, waiting in the queue's
native timed `get`, is woken directly, one thread wake-up a message. A receive takes the newest sample and drops
(counts) any older ones still queued, so the consumer never works through a backlog. The former design, a Python
callable run by zenoh-python's own callback thread that swapped a slot and notified a condition, took two wake-ups
and cost 17-33 us a hop more (docs/timing.md, "Zenoh hop").
"""
from __future__ import annotations

import queue

import zenoh

__all__ = ["LatestSubscriber"]


class LatestSubscriber:
    """`recv(timeout_s)` returns the newest sample that arrived since the last receive, waiting up to `timeout_s`
    for one (None: nothing came; 0: without waiting). `overwritten` counts the samples a newer
    one replaced before anyone read them. Samples wait in the queue only between two receives."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.key = key
        self.overwritten = 0
        self._queue: queue.SimpleQueue[zenoh.Sample] = queue.SimpleQueue()
        self._sub = session.declare_subscriber(key, zenoh.handlers.Callback(self._queue.put, indirect=False))
        self._closed = False

    def _newest(self, sample: zenoh.Sample) -> zenoh.Sample:
        q = self._queue
        while not q.empty():
            sample = q.get_nowait()
            self.overwritten += 1
        return sample

    def recv(self, timeout_s: float) -> zenoh.Sample | None:
        try:
            return self._newest(self._queue.get(timeout=max(0.0, timeout_s)))
        except queue.Empty:
            return None

    def close(self) -> None:
        """Idempotent: no sample is queued after it."""
        if not self._closed:
            self._closed = True
            self._sub.undeclare()

    def __enter__(self) -> LatestSubscriber:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

"""The newest-sample-only subscribers: `LatestHandler`, the real-time controller's (states handled in zenoh's receiving
thread when nothing is behind them), and `LatestSubscriber` (a consumer thread receives them).

zenoh runs the subscriber's callback in its own receiving thread (`Callback(..., indirect=False)`), and the callback
is `queue.SimpleQueue.put`, C code: no Python frame runs for an arrival, and the consumer, waiting in the queue's
native timed `get`, is woken directly, one thread wake-up a message. A receive takes the newest sample and drops
(counts) any older ones still queued, so the consumer never works through a backlog. The former design, a Python
callable run by zenoh-python's own callback thread that swapped a slot and notified a condition, took two wake-ups
and cost 17-33 us a hop more (docs/timing.md, "Zenoh hop").

`LatestHandler` saves the consumer's wake-up too (docs/timing.md, "Closed loop"): a sample that finds nothing queued
and no handling under way is handled at once in zenoh's receiving thread; only when the handler is behind (a sample
queued, a handling under way in the consumer, or the sample sent before the receiving thread's previous handling
ended, so it may have waited behind it while a newer one is on its way) does it queue, and the consumer's `serve`
takes the newest queued one, as `LatestSubscriber.recv` does.
"""
from __future__ import annotations

import itertools
import queue
import threading
import time
from collections.abc import Callable

import zenoh

__all__ = ["LatestHandler", "LatestSubscriber"]


class LatestSubscriber:
    """`recv(timeout_s)` returns the newest sample that arrived since the last receive, waiting up to `timeout_s`
    for one (None: nothing came); `try_latest()` the same without waiting. `overwritten` counts the samples a newer
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

    def try_latest(self) -> zenoh.Sample | None:
        try:
            return self._newest(self._queue.get_nowait())
        except queue.Empty:
            return None

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


class LatestHandler:
    """Newest-only samples (payload bytes) of `key` handled by `handle(data)`, one at a time: in zenoh's receiving
    thread when the sample finds nothing queued, no handling under way and was sent (`sent_ns(data)`, the sender's
    monotonic clock, shared with this host's or synchronised; None: unknown) no earlier than the end of the previous
    handling there; otherwise queued for `serve`. `overwritten` counts the samples a newer one replaced before they
    were handled (queued ones drained by `serve`, and a queued one older than one handled meanwhile); `inline` the
    samples handled in the receiving thread. Samples are handled on arrival only between `start()` and `stop()` (the
    consumer's loop); before and after they queue, as for `LatestSubscriber`. An exception of `handle` in the
    receiving thread is raised again by the next `serve`."""

    def __init__(self, session: zenoh.Session, key: str, handle: Callable[[bytes], object],
                 sent_ns: Callable[[bytes], int | None]) -> None:
        self.key = key
        self.overwritten = 0
        self.inline = 0
        self.handled = 0                # samples handled, in either thread
        self._handle, self._sent_ns = handle, sent_ns
        self._queue: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        self._lock = threading.Lock()   # one handling at a time
        self._arrivals = itertools.count(1)   # arrival index of each sample (`next` is atomic: several links)
        self._handled_index = 0         # arrival index of the newest sample handled
        self._inline_end_ns = 0         # monotonic end of the receiving thread's latest handling
        self._seen = 0                  # `handled` at the previous `serve`
        self._error: BaseException | None = None
        self._on_arrival = False        # between `start` and `stop`
        self._sub = session.declare_subscriber(key, zenoh.handlers.Callback(self._on_sample, indirect=False))
        self._closed = False

    def _on_sample(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        index = next(self._arrivals)
        if self._on_arrival and self._queue.empty() and self._error is None:
            sent = self._sent_ns(data)
            if sent is not None and sent >= self._inline_end_ns and self._lock.acquire(blocking=False):
                try:
                    self._run(index, data)
                    self.inline += 1
                except Exception as err:   # raised again in the consumer's thread (`serve`)
                    self._error = err
                finally:
                    self._inline_end_ns = time.monotonic_ns()
                    self._lock.release()
                return
        self._queue.put((index, data))

    def _run(self, index: int, data: bytes) -> None:
        self._handled_index = index
        self.handled += 1
        self._handle(data)

    @property
    def queued(self) -> int:
        """Samples waiting for `serve`."""
        return self._queue.qsize()

    def start(self) -> None:
        """Handle samples on arrival from now on (when nothing is behind them)."""
        self._on_arrival = True

    def stop(self) -> None:
        """Queue every sample from now on (a handling under way in the receiving thread completes)."""
        self._on_arrival = False

    def serve(self, timeout_s: float) -> bool:
        """Handle the newest queued sample, waiting up to `timeout_s` for one; True if any sample was handled since the
        previous call (here or in the receiving thread)."""
        if self._error is not None:
            err, self._error = self._error, None
            raise err
        try:
            index, data = self._queue.get(timeout=max(0.0, timeout_s))
        except queue.Empty:
            return self._progressed()
        with self._lock:
            while not self._queue.empty():
                index, data = self._queue.get_nowait()
                self.overwritten += 1
            if index < self._handled_index:    # a newer one was handled in the receiving thread meanwhile
                self.overwritten += 1
            else:
                self._run(index, data)
        return self._progressed()

    def _progressed(self) -> bool:
        handled = self.handled
        progressed, self._seen = handled != self._seen, handled
        return progressed

    def close(self) -> None:
        """Idempotent: nothing is handled or queued after it."""
        if not self._closed:
            self._closed = True
            self._sub.undeclare()

    def __enter__(self) -> LatestHandler:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

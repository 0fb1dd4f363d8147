"""The newest-sample-only subscriber the real-time controller receives states with (`LatestSubscriber`).

zenoh's `RingChannel` keeps only the newest samples, and the receiving thread blocks in zenoh's own `recv()` with
the GIL released, so an arriving sample wakes it directly: one thread wake-up a message. (The former design, a
Python callback swapping a slot and notifying a condition, took two, and cost 17-33 us a hop: docs/timing.md,
"Zenoh hop".) zenoh-python's `recv()` has no timeout, so a timed `recv(timeout_s)` is given by a waker thread: when
a receive has waited `timeout_s`, it puts an empty sample marked with this subscriber's own random attachment on
the same key, delivered to this session only (`Locality.SESSION_LOCAL`: no peer, no recorder sees it). The ring is
two deep, so a wake-up never displaces a real sample; every receive drains it and returns the newest real one.
"""
from __future__ import annotations

import os
import threading
import time

import zenoh

__all__ = ["LatestSubscriber"]


class LatestSubscriber:
    """`recv(timeout_s)` blocks until a sample arrives (the newest, None after `timeout_s`, give or take the waker's
    `poll_s`, or once closed); `try_latest()` takes the newest unread sample or None. Samples replaced before anyone
    read them are dropped by the ring. One receiving thread at a time; `close()` may come from any thread."""

    def __init__(self, session: zenoh.Session, key: str, *, poll_s: float = 0.01) -> None:
        self.key = key
        self.wakeups = 0                            # receives ended by the waker (timeouts and close)
        self._token = os.urandom(8)
        self._sub = session.declare_subscriber(key, zenoh.handlers.RingChannel(2))
        self._wake = session.declare_publisher(key, allowed_destination=zenoh.Locality.SESSION_LOCAL)
        self._recv_lock = threading.Lock()          # held by the receiving thread; close() waits for it
        self._waiting_until_ns = 0                  # the receive's deadline while one waits, else 0
        self._closed = threading.Event()
        self._poll_s = poll_s
        self._waker = threading.Thread(target=self._wake_loop, name=f"wake {key}", daemon=True)
        self._waker.start()

    def _is_wake(self, sample: zenoh.Sample) -> bool:
        att = sample.attachment
        return att is not None and att.to_bytes() == self._token and not sample.payload.to_bytes()

    def _drain(self, sample: zenoh.Sample | None) -> zenoh.Sample | None:
        """The newest real sample among `sample` and everything the ring holds."""
        newest = None if sample is None or self._is_wake(sample) else sample
        while (more := self._sub.try_recv()) is not None:
            if not self._is_wake(more):
                newest = more
        return newest

    def try_latest(self) -> zenoh.Sample | None:
        with self._recv_lock:
            return None if self._closed.is_set() else self._drain(None)

    def recv(self, timeout_s: float) -> zenoh.Sample | None:
        with self._recv_lock:
            if self._closed.is_set():
                return None
            sample = self._drain(None)
            if sample is not None:
                return sample
            self._waiting_until_ns = time.monotonic_ns() + int(timeout_s * 1e9)
            try:
                got = self._sub.recv()
            finally:
                self._waiting_until_ns = 0
            return self._drain(got)

    def _wake_loop(self) -> None:
        while not self._closed.wait(self._poll_s):
            until = self._waiting_until_ns
            if until and time.monotonic_ns() >= until:
                self._waiting_until_ns = 0
                self._put_wake()

    def _put_wake(self) -> None:
        self.wakeups += 1
        try:
            self._wake.put(b"", attachment=self._token)
        except zenoh.ZError:            # the session is closed: no receive can wait on it any more
            pass

    def close(self) -> None:
        """Idempotent: ends a receive under way (a wake-up), stops the waker, undeclares."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._waker.join(timeout=2.0)
        self._put_wake()                # a receive blocked right now returns; later ones see `_closed`
        while not self._recv_lock.acquire(timeout=0.05):   # (one that drained the wake-up just before blocking)
            self._put_wake()
        try:
            self._wake.undeclare()
            self._sub.undeclare()
        finally:
            self._recv_lock.release()

    def __enter__(self) -> LatestSubscriber:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

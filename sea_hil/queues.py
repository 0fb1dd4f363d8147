"""A timed get on `queue.SimpleQueue` that cannot hang: `timed_get(q, timeout_s)`.

CPython's C `SimpleQueue.get(timeout=T)` (seen on 3.11.7) can block forever. When it is entered with the queue
empty and its internal lock free (a `put` released the lock while no getter was waiting), its first non-blocking
acquire succeeds, the list is still empty, and it recomputes the remaining timeout; if the deadline has passed in
between (a thread preempted for T, likely for sub-millisecond T on a loaded machine) that timeout is negative,
and a negative timeout means "wait forever": the call returns only at the next `put`. The driver node waits for
its next tick with timeouts below 1 ms in `FastVirtualBus.recv`, and the next frame on its queue is a
VOLTAGE_CMD that the edge sends only after the driver's feedback: the whole session stopped (issue 18's stall;
docs/reliability.md). A `get_nowait()` first leaves the lock taken whenever the queue is empty, so the timed
`get` that follows starts waiting with its full, positive timeout. One consumer per queue (as every user here has:
one receiving thread per bus handle, one waiting thread per inbox).
"""
from __future__ import annotations

import queue
from typing import TypeVar

T = TypeVar("T")


def timed_get(q: queue.SimpleQueue[T], timeout_s: float | None) -> T:
    """`q.get(timeout=timeout_s)` (None: block) without CPython's hang; `queue.Empty` after `timeout_s`."""
    try:
        return q.get_nowait()
    except queue.Empty:
        if timeout_s is not None and timeout_s <= 0:
            raise
    return q.get(timeout=timeout_s)

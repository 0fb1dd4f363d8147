"""`sea_hil.queues.timed_get` and the virtual CAN bus's receive never hang on an empty queue (the stall of issue 18:
CPython's `SimpleQueue.get(timeout=)` could wait forever, see sea_hil/queues.py). The pattern that triggers it is
repeated many times: a put with no getter waiting (the internal lock is left free), the item taken, then a timed
get on the empty queue with a timeout so short that its deadline passes inside the call. The plain
`SimpleQueue.get(timeout=1e-6)` hung in this loop within 69-4690 iterations (CPython 3.11.7, 4 runs)."""
from __future__ import annotations

import queue
import threading
import uuid

import can

from sea_hil.protocol.canbus import open_bus
from sea_hil.queues import timed_get

ROUNDS = 8_000
DEADLINE_S = 60.0   # ~0.3 s normally; a hang never ends


def _in_thread(fn) -> bool:
    """True if `fn` finished within the deadline (a hung call leaves its daemon thread behind, blocked)."""
    done = threading.Event()
    threading.Thread(target=lambda: (fn(), done.set()), daemon=True).start()
    return done.wait(DEADLINE_S)


def test_timed_get_returns_on_an_empty_queue() -> None:
    q: queue.SimpleQueue[int] = queue.SimpleQueue()
    empties = [0]

    def loop() -> None:
        for k in range(ROUNDS):
            q.put(k)
            assert timed_get(q, 1e-6) == k
            try:
                timed_get(q, 1e-6)
            except queue.Empty:
                empties[0] += 1
    assert _in_thread(loop), "timed_get hung on an empty queue"
    assert empties[0] == ROUNDS


def test_timed_get_zero_and_blocking() -> None:
    q: queue.SimpleQueue[int] = queue.SimpleQueue()
    for t in (0.0, -1.0):
        try:
            timed_get(q, t)
            raise AssertionError("no item, no wait: Empty expected")
        except queue.Empty:
            pass
    threading.Timer(0.05, q.put, (7,)).start()
    assert timed_get(q, None) == 7


def test_virtual_bus_receive_with_short_timeouts_never_hangs() -> None:
    channel = f"queues-{uuid.uuid4().hex[:8]}"
    rx, tx = open_bus(f"virtual:{channel}"), open_bus(f"virtual:{channel}")
    got = [0]

    def loop() -> None:
        for k in range(ROUNDS):
            tx.send(can.Message(arbitration_id=0x10, data=bytes([k % 256]), is_extended_id=False))
            assert rx.recv(timeout=1e-6) is not None
            assert rx.recv(timeout=1e-6) is None   # the driver's wait for its next tick, with nothing queued
            got[0] += 1
    try:
        assert _in_thread(loop), "FastVirtualBus.recv hung on an empty queue"
        assert got[0] == ROUNDS
    finally:
        rx.shutdown()
        tx.shutdown()

"""`receive_stamped` (controller/edge.py), the CAN receive of the edge and of the per-bus `EdgeMux`: a frame
comes with its monotonic arrival time; a receive error is handed to the node's counter and log, the call waits on
the stop event and returns nothing, so the node keeps running."""
from __future__ import annotations

import threading
import time

import can

from sea_hil.controller.edge import receive_stamped


class _Bus:
    def __init__(self, *results: object) -> None:
        self.results = list(results)

    def recv(self, timeout: float) -> can.Message | None:
        r = self.results.pop(0)
        if isinstance(r, Exception):
            raise r
        return r


class _Stop:
    def __init__(self) -> None:
        self.waits: list[float] = []

    def wait(self, timeout_s: float) -> bool:
        self.waits.append(timeout_s)
        return False


def test_a_frame_comes_with_its_arrival_time_and_an_error_is_counted_not_raised() -> None:
    sent_wall_s = time.time() - 0.002
    frame = can.Message(arbitration_id=0x21, data=b"\x00" * 8, timestamp=sent_wall_s)
    errors: list[Exception] = []
    stop = _Stop()
    bus = _Bus(frame, None, can.CanOperationError("interface down"), OSError("ENETDOWN"))
    before_ns = time.monotonic_ns()
    msg, rx_ns = receive_stamped(bus, stop, errors.append)
    assert msg is frame
    # stamped 2 ms before the call: the arrival is ~2 ms before now on the monotonic clock, not the call's time
    assert before_ns - 10_000_000 < rx_ns < before_ns - 1_000_000
    assert receive_stamped(bus, stop, errors.append) is None and stop.waits == []      # nothing within the timeout
    assert receive_stamped(bus, stop, errors.append, timeout_s=0.01) is None
    assert receive_stamped(bus, stop, errors.append) is None
    assert [type(e) for e in errors] == [can.CanOperationError, OSError]
    assert stop.waits == [0.01, 0.05]                  # each error backs off on the stop event


def test_a_stopped_node_does_not_back_off() -> None:
    stop = threading.Event()
    stop.set()
    t0 = time.monotonic()
    assert receive_stamped(_Bus(can.CanOperationError("down")), stop, lambda _e: None, timeout_s=5.0) is None
    assert time.monotonic() - t0 < 4.0

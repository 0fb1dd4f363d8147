"""CAN bus error in the guest: `ip link set vcan0 down` under a running driver node -> the failed sends/receives are
counted and flagged (BUS_ERROR in the heartbeat), the node keeps running, and feedback flows again after
`ip link set vcan0 up`. Functional, not timing-bound (guest syscalls are slow); the recovery time is printed."""
from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Callable

import can
from socketcan_helpers import PROCESS_TIMEOUT_S

from sea_hil.config.loader import load_config
from sea_hil.errors import MalformedFrame
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import ErrorFlags, FeedbackAngle, Heartbeat

NODE = 1
WAIT_S = 30.0


def _link(channel: str, state: str) -> None:
    subprocess.run(["ip", "link", "set", channel, state], check=True, capture_output=True, timeout=PROCESS_TIMEOUT_S)


def _wait(cond: Callable[[], bool], timeout_s: float) -> bool:
    tick, deadline = threading.Event(), time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            return False
        tick.wait(0.01)
    return True


def _next_of(bus: can.BusABC, codec: SeaCodec, kind: type, timeout_s: float) -> object | None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            msg = bus.recv(timeout=0.1)
        except can.CanOperationError:   # the monitor's socket also reports the ENETDOWN it saw
            continue
        if msg is None:
            continue
        try:
            frame = codec.decode(msg)
        except MalformedFrame:
            continue
        if isinstance(frame, kind):
            return frame
    return None


def test_interface_down_is_counted_flagged_and_survived(vcan_channel: str,
                                                        open_can_bus: Callable[..., can.BusABC]) -> None:
    cfg = load_config(None, {"can": {"interface": f"socketcan:{vcan_channel}", "feedback_rate_hz": 100.0}})
    node = PlantNode(cfg, open_can_bus(), (NODE,))
    monitor, codec = open_can_bus(), SeaCodec([NODE])
    thread = threading.Thread(target=node.run, daemon=True)
    thread.start()
    try:
        assert _next_of(monitor, codec, FeedbackAngle, WAIT_S) is not None, "no feedback before the fault"
        _link(vcan_channel, "down")
        assert _wait(lambda: node.stats.bus_errors > 0, WAIT_S), "interface down went unnoticed"
        assert ErrorFlags.BUS_ERROR in node.drivers[NODE].flags and thread.is_alive()
        up_at = time.monotonic()
        _link(vcan_channel, "up")
        hb = None    # frames queued before the fault may still be in the monitor's socket: skip to a fresh one
        while hb is None or ErrorFlags.BUS_ERROR not in hb.flags:
            hb = _next_of(monitor, codec, Heartbeat, WAIT_S)
            assert isinstance(hb, Heartbeat), "no heartbeat reporting the bus error after link up"
        recovered_ms = (time.monotonic() - up_at) * 1e3
        assert _next_of(monitor, codec, FeedbackAngle, WAIT_S) is not None and thread.is_alive()
        print(f"\nbus down: {node.stats.bus_errors} bus errors, {node.stats.send_failures} failed sends; "
              f"link up -> BUS_ERROR heartbeat received {recovered_ms:.0f} ms")
    finally:
        _link(vcan_channel, "up")
        node.stop()
        thread.join(timeout=PROCESS_TIMEOUT_S)

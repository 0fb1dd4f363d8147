"""The recorder's CAN tap on a real SocketCAN socket: it asks for a large receive buffer, and the frames the kernel
drops when the tap's receive queue overflows are counted exactly from the driver frames' seq gaps
(`can_frames_missed`).

The overflow is provoked with the smallest receive buffer the kernel grants and a tap that does not read while a
burst is sent; the tap then drains the queue. One frame per id before the burst and one after it (each sent and read
back one at a time, so none is dropped) give every id's seq a reference and expose its trailing gap.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

import can
import pytest

from sea_hil.config.loader import load_config
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import FeedbackAngle
from sea_hil.protocol.canbus import RX_BUFFER_BYTES, send_with_retry
from sea_hil.recorder.node import RecorderNode
from sea_hil.recorder.writer import SessionRecorder

NODES = tuple(range(1, 17))
ROUNDS = 50                 # < 256: one id's run of drops cannot alias the 8-bit seq
IDLE_S = 0.5
MARKER_TIMEOUT_S = 10.0


def _send(bus: can.BusABC, codec: SeaCodec, node_id: int, seq: int) -> None:
    send_with_retry(bus, codec.encode(FeedbackAngle(node_id, seq, seq, (0.0, 0.0))), 1000, 0.001)  # vcan tx queue full


def _drain_until(bus: can.BusABC, node: RecorderNode, done: Callable[[can.Message], bool] | None) -> None:
    """Feed received frames to the node until `done(frame)` (AssertionError at the deadline) or, with no `done`,
    until the queue stays empty for IDLE_S."""
    deadline = time.monotonic() + MARKER_TIMEOUT_S
    while time.monotonic() < deadline:
        msg = bus.recv(timeout=IDLE_S)
        if msg is None:
            if done is None:
                return
            continue
        node.on_can(msg)
        if done is not None and done(msg):
            return
    raise AssertionError("the tap did not receive the expected frame in time")


def _one_at_a_time(sender: can.BusABC, tap_bus: can.BusABC, node: RecorderNode, codec: SeaCodec, seq: int) -> None:
    """Send frame `seq` of every id, each read back by the tap before the next is sent (so none is dropped)."""
    for n in NODES:
        _send(sender, codec, n, seq)
        marker = FeedbackAngle(n, seq, seq, (0.0, 0.0))
        _drain_until(tap_bus, node, lambda m, marker=marker: codec.decode(m) == marker)


def test_tap_asks_for_a_large_receive_buffer(tmp_path: Path, open_can_bus: Callable[..., can.BusABC]) -> None:
    if os.geteuid() != 0:
        pytest.skip("SO_RCVBUFFORCE needs root (the UML guest runs as root)")
    with SessionRecorder.from_config(tmp_path / "r.mcap", load_config().record) as rec:
        node = RecorderNode(rec, None, "sea", open_can_bus())
        assert node.rx_buffer_bytes is not None and node.rx_buffer_bytes >= RX_BUFFER_BYTES
        assert node.counters()["can_rx_buffer_bytes"] == node.rx_buffer_bytes


def test_kernel_drops_are_counted_as_missed_frames(tmp_path: Path,
                                                   open_can_bus: Callable[..., can.BusABC]) -> None:
    codec, tap_bus, sender = SeaCodec(), open_can_bus(), open_can_bus()
    with SessionRecorder.from_config(tmp_path / "d.mcap", load_config().record) as rec:
        node = RecorderNode(rec, None, "sea", tap_bus, rx_buffer_bytes=1)   # the kernel's minimum
        _one_at_a_time(sender, tap_bus, node, codec, 0)    # every id's first frame: the reference of its seq
        for seq in range(1, ROUNDS + 1):                   # burst while the tap does not read
            for n in NODES:
                _send(sender, codec, n, seq)
        _drain_until(tap_bus, node, None)
        _one_at_a_time(sender, tap_bus, node, codec, ROUNDS + 1)   # exposes each id's trailing gap
        c = node.counters()
    sent = (ROUNDS + 2) * len(NODES)
    print(f"\nrx buffer {c['can_rx_buffer_bytes']} B: {c['can_frames']} of {sent} frames received, "
          f"{c['can_frames_missed']} counted missed")
    assert c["can_frames_missed"] > 0, c      # the tiny buffer did overflow
    assert c["can_frames"] + c["can_frames_missed"] == sent, c
    assert c["can_rejected"] == 0

"""One wake per tick (issue 33): the virtual bus's batch send and one-pass read (`FastVirtualBus.send_batch`,
`canbus.recv_pending`), and the driver handling the frames queued in a period at their arrival times. In-process,
milliseconds."""
from __future__ import annotations

import time
from typing import Any

import can
from hypothesis import given, settings
from hypothesis import strategies as st

from sea_hil.config.loader import load_config
from sea_hil.errors import MalformedFrame
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import CMD_BITS, Feedback, VoltageCmd
from sea_hil.protocol.canbus import FastVirtualBus, batches, open_bus, recv_pending, send_all
from sea_hil.protocol.merged_bus import MergedBus


def test_a_batch_reaches_every_reader_once_in_order_and_a_pending_read_takes_all() -> None:
    """`send_batch` (a driver tick's frames): one queue item per fast reader, unbatched by `recv` and
    `recv_pending`; a plain python-can reader on the channel gets the frames one by one; a `TimedBus` is read
    through its own `recv`, never its raw bus's `recv_pending` (canbus.recv_pending asks the type)."""
    a, b, c = (open_bus("virtual:hotpath-batch") for _ in range(3))
    plain = can.Bus(interface="virtual", channel="hotpath-batch")
    try:
        assert batches(a) is False                       # a bounded python-can queue on the channel: frame by frame
        plain.shutdown()
        assert batches(a)
        frames = [can.Message(arbitration_id=i, data=bytes([i]), is_extended_id=False) for i in range(4)]
        send_all(a, frames[:3])
        assert b.queue.qsize() == 1                      # one item: the reader wakes once for the batch
        send_all(a, frames[3:])
        assert [m.arbitration_id for m in recv_pending(b)] == [0, 1, 2, 3] and recv_pending(b) == []
        got = [c.recv(0) for _ in range(5)]
        assert [m.arbitration_id for m in got[:4]] == [0, 1, 2, 3] and got[4] is None
        assert len({m.timestamp for m in got[:3]}) == 1 and got[0] is not frames[0]   # one send time, copies
        assert recv_pending(a) == []                     # not its own messages
    finally:
        for bus in (a, b, c, plain):
            bus.shutdown()



def test_the_driver_takes_a_command_at_its_arrival_time_not_at_its_wake() -> None:
    """`PlantNode.take_pending` at the tick's wake: a VOLTAGE_CMD that arrived 0.3 ms into the period acts from that
    offset (its bus stamp), as if it had been handled when it came; the period's feedback left in one send."""
    cfg = load_config()
    bus = open_bus("virtual:hotpath-take")
    edge = FastVirtualBus(channel="hotpath-take", preserve_timestamps=True)
    node = PlantNode(cfg, bus, (1,))
    try:
        drv = node.drivers[1]
        node.publish_samples([(drv, drv.feedback())])
        assert drv.period_start_ns is None and recv_pending(edge) == []   # encoded, not sent: sent as it sleeps
        node.wait_until(0)
        assert drv.period_start_ns is not None and len(recv_pending(edge)) == 3   # 3 classic feedback frames, at once
        cmd = SeaCodec.for_bus(cfg.can).encode(VoltageCmd(1, (1.0, -1.0), 0))
        mono_ns, wall_ns = time.monotonic_ns(), time.time_ns()
        drv.period_start_ns = mono_ns - 800_000        # the period began 0.8 ms ago ...
        cmd.timestamp = (wall_ns - 500_000) * 1e-9     # ... the command came 0.5 ms ago: 0.3 ms in
        edge.send(cmd)
        node.take_pending(time.monotonic_ns())
        (offset, u), = drv._changes
        assert u == (1.0, -1.0) and drv.counters.commands == 1
        assert 250_000 <= offset < 700_000               # the arrival (0.3 ms in), not the wake (>= 0.8 ms in)
    finally:
        bus.shutdown()
        edge.shutdown()


def test_a_merged_bus_reads_batches_and_sends_each_bus_its_frames() -> None:
    names = [f"virtual:tick-merged-{i}" for i in range(2)]
    mine, peers = [open_bus(n) for n in names], [open_bus(n) for n in names]
    merged = MergedBus({1: mine[0], 2: mine[1]})
    try:
        assert batches(merged)
        send_all(peers[0], [_frame(1, b"a"), _frame(1, b"b")])
        send_all(peers[1], [_frame(2, b"c")])
        assert bytes(merged.recv(0.1).data) == b"a"      # the first of a batch; its rest stays in order
        assert [bytes(m.data) for m in recv_pending(merged)] == [b"b", b"c"] and merged.recv(0) is None
        send_all(merged, [_frame(2, b"x"), _frame(1, b"y"), _frame(2, b"z")])
        assert [bytes(m.data) for m in recv_pending(peers[1])] == [b"x", b"z"]   # node 2's bus only, in order
        assert [bytes(m.data) for m in recv_pending(peers[0])] == [b"y"]
    finally:
        for bus in (*mine, *peers):
            bus.shutdown()


def _frame(node_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=(node_id << CMD_BITS) | 1, data=data, is_extended_id=False)


@settings(max_examples=300, deadline=None)
@given(values=st.lists(st.one_of(st.floats(-20, 20), st.floats(allow_nan=True, allow_infinity=True)), min_size=8,
                       max_size=8),
       seq=st.integers(-1, 300), t_us=st.integers(-1, 70000), saturate=st.booleans())
def test_the_direct_feedback_encoding_is_the_parts_encoding(values: list[float], seq: int, t_us: int,
                                                           saturate: bool) -> None:
    """`SeaCodec.encode_feedback` (classic) packs the parts' values straight from the sample: the same frames, or
    the same error, as encoding `fb.parts()` one by one, in range or not."""
    codec = SeaCodec()
    v = values
    fb = Feedback(3, seq, t_us, (v[0], v[1]), (v[2], v[3]), (v[4] * 1e-3, v[5] * 1e-3), (v[6], v[7]))

    def outcome(encode: Any) -> Any:
        try:
            return [(m.arbitration_id, bytes(m.data), m.is_fd, m.bitrate_switch, m.dlc) for m in encode()]
        except MalformedFrame as err:
            return str(err)
    assert outcome(lambda: codec.encode_feedback(fb, saturate=saturate)) == \
        outcome(lambda: [codec.encode(p, saturate=saturate) for p in fb.parts()])

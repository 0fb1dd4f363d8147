"""`MergedBus` (issue 17): several CAN buses read by one thread; frames keep to their own bus, sends go to the bus of
their node id, and what cannot be merged is refused. Pure in-process (`virtual:` buses), milliseconds."""
from __future__ import annotations

import uuid

import can
import pytest

from sea_hil.errors import BusError
from sea_hil.protocol.can_frames import CMD_BITS
from sea_hil.protocol.canbus import open_bus
from sea_hil.protocol.merged_bus import MergedBus, can_merge
from sea_hil.protocol.timed_bus import TimedBus


def _frame(node_id: int, cmd: int = 1, data: bytes = b"\x01") -> can.Message:
    return can.Message(arbitration_id=(node_id << CMD_BITS) | cmd, data=data, is_extended_id=False)


def _two_buses() -> tuple[list[str], dict[str, can.BusABC], dict[str, can.BusABC]]:
    names = [f"virtual:merged-{uuid.uuid4().hex}" for _ in range(2)]
    mine = {n: open_bus(n) for n in names}     # the handles the merged bus reads
    peers = {n: open_bus(n) for n in names}    # another node's handle on each bus
    return names, mine, peers


def test_receives_from_every_bus_and_sends_to_the_bus_of_the_node() -> None:
    names, mine, peers = _two_buses()
    merged = MergedBus({1: mine[names[0]], 2: mine[names[1]]})
    peers[names[0]].send(_frame(1, data=b"a"))
    peers[names[1]].send(_frame(2, data=b"b"))
    peers[names[0]].send(_frame(1, data=b"c"))
    got = [merged.recv(0.1) for _ in range(3)]
    assert [bytes(m.data) for m in got if m is not None] == [b"a", b"b", b"c"]   # one bus's frames keep their order
    assert merged.recv(0) is None
    merged.send(_frame(2, data=b"x"))
    assert peers[names[0]].recv(0) is None                  # not on node 1's bus
    assert bytes(peers[names[1]].recv(0.1).data) == b"x"    # on node 2's
    with pytest.raises(can.CanOperationError, match="no bus for node 3"):
        merged.send(_frame(3))
    for b in (*mine.values(), *peers.values()):
        b.shutdown()


def test_a_bus_frames_still_reach_only_its_own_handles() -> None:
    names, mine, peers = _two_buses()
    other = {n: open_bus(n) for n in names}   # a third handle per bus (e.g. the recorder's tap)
    merged = MergedBus({1: mine[names[0]], 2: mine[names[1]]})
    merged.send(_frame(1))
    assert merged.recv(0) is None                     # not back to the sender
    assert peers[names[0]].recv(0.1) is not None and other[names[0]].recv(0.1) is not None
    assert peers[names[1]].recv(0) is None and other[names[1]].recv(0) is None
    for b in (*mine.values(), *peers.values(), *other.values()):
        b.shutdown()


def test_what_cannot_be_merged_is_refused() -> None:
    names, mine, _peers = _two_buses()
    timed = TimedBus.__new__(TimedBus)   # the bus-timing model's wrapper: no shared queue, no file descriptor
    assert can_merge(mine.values()) and not can_merge([*mine.values(), timed])
    with pytest.raises(BusError, match="cannot be read as one"):
        MergedBus({1: mine[names[0]], 2: timed})
    with pytest.raises(BusError, match="at least one route"):
        MergedBus({})

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


def _compose(lockstep: bool = False, merge: bool = True):  # type: ignore[no-untyped-def]
    from sea_hil.config.loader import load_config
    from sea_hil.session.builder import SessionBuilder
    from sea_hil.session.limb_nodes import build_limb_nodes
    from sea_hil.session.limbs import expand_limbs
    cfg = load_config(overrides={"can": {"interface": f"virtual:mb-{uuid.uuid4().hex[:8]}"},
                                 "timing": {"merge_buses": merge}})
    b = SessionBuilder(cfg, lockstep=lockstep)
    session = b.zenoh(listen=(), connect=())
    return b, build_limb_nodes(b, session, expand_limbs(cfg, 2), "edge")


def test_real_time_limbs_on_two_buses_share_one_driver_edge_and_tap() -> None:
    from sea_hil.controller.edge_mux import EdgeMux
    b, nodes = _compose()
    with b:
        assert len(nodes.buses) == 2 and len(nodes.plants) == len(nodes.runners) == len(nodes.taps) == 1
        plant, mux, tap = nodes.plants[0], nodes.runners[0], nodes.taps[0]
        assert tuple(plant.drivers) == (1, 2) and isinstance(mux, EdgeMux) and isinstance(tap, MergedBus)
        for drv, fb in plant.step_drivers():   # each limb's feedback on its own bus
            plant.publish(drv, fb)
        while (msg := mux.bus.recv(0.1)) is not None:
            mux.dispatch(msg, 1)
        assert [e.core.counters.feedback for e in nodes.edges] == [1, 1]
        ids = []
        while (msg := tap.recv(0)) is not None:
            ids.append(msg.arbitration_id >> CMD_BITS)
        assert sorted(set(ids)) == [1, 2] and len(ids) == 2 * len(ids) // 2 > 2


def test_lockstep_and_merge_off_keep_one_driver_per_bus() -> None:
    for lockstep, merge in ((True, True), (False, False)):
        b, nodes = _compose(lockstep, merge)
        with b:
            assert len(nodes.plants) == len(nodes.taps) == 2
            assert [tuple(p.drivers) for p in nodes.plants] == [(1,), (2,)]


def test_a_failed_send_flags_only_the_drivers_on_that_bus() -> None:
    from sea_hil.config.loader import load_config
    from sea_hil.plant_emulator.node import PlantNode
    from sea_hil.protocol.can_frames import ErrorFlags
    names, mine, peers = _two_buses()
    plant = PlantNode(load_config(), MergedBus({1: mine[names[0]], 2: mine[names[1]]}), (1, 2))
    mine[names[1]].shutdown()   # node 2's bus fails
    for drv, fb in plant.step_drivers():
        plant.publish(drv, fb)
    assert {n: bool(d.flags & ErrorFlags.BUS_ERROR) for n, d in plant.drivers.items()} == {1: False, 2: True}
    assert plant.stats.send_failures == 3 and plant.stats.bus_errors == 3   # node 2's three feedback frames
    for b in (mine[names[0]], *peers.values()):
        b.shutdown()

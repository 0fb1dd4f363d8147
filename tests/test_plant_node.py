"""Tests of plant_emulator/node.py: `PlantNode` over python-can `virtual` buses (one unique channel per test).

The node runs in a thread and is ended with `stop()` + join; the test side waits on received frames with deadlines.
Malformed-frame properties feed `PlantNode._on_message` directly (fast); one end-to-end check goes over the bus.
"""
from __future__ import annotations

import struct
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.dynamics import initial_state
from sea_hil.errors import MalformedFrame
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.integrator import advance
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.can_assembly import FeedbackAssembler
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import (
    FEEDBACK_PARTS,
    ClearErrors,
    DriverState,
    ErrorFlags,
    Feedback,
    FeedbackAngle,
    Heartbeat,
    VoltageCmd,
)
from sea_hil.protocol.canbus import open_bus
from sea_hil.session.builder import SessionBuilder

NODE = 1
THETA_LSB_RAD = 1e-4
FAST_RT = {"can": {"feedback_rate_hz": 200.0, "heartbeat_rate_hz": 50.0, "watchdog_timeout_s": 0.05}}
DLC_OF_CMD = {m.frame_id & 0x1F: m.length for m in load_database().messages}


class Peer:
    """The test's end of the bus: decodes what the node sends, sends frames to it."""

    def __init__(self, bus: can.BusABC, node_ids: tuple[int, ...] = (NODE,)) -> None:
        self.bus, self.codec, self.assembler = bus, SeaCodec(node_ids), FeedbackAssembler()

    def send(self, frame: Any) -> None:
        self.bus.send(self.codec.encode(frame))

    def wait_for(self, pred: Callable[[Any], bool], timeout_s: float,
                 on_frame: Callable[[Any], None] | None = None) -> Any:
        """First decoded frame (or assembled `Feedback`) satisfying `pred`; AssertionError at the deadline."""
        deadline = time.monotonic_ns() + int(timeout_s * 1e9)
        while (remaining := deadline - time.monotonic_ns()) > 0:
            msg = self.bus.recv(timeout=remaining * 1e-9)
            if msg is None:
                continue
            frame = self.codec.decode(msg)  # the node must only send well-formed frames
            if on_frame is not None:
                on_frame(frame)
            if isinstance(frame, FEEDBACK_PARTS):
                frame = self.assembler.push(frame) or frame
            if pred(frame):
                return frame
        raise AssertionError(f"no matching frame within {timeout_s} s")


@contextmanager
def running_plants(cfg: SeaHilConfig, served: tuple[tuple[int, ...], ...], *,
                   lockstep: bool) -> Iterator[tuple[list[PlantNode], Peer]]:
    """One running `PlantNode` per entry of `served` (its node ids), all on one fresh virtual bus, and a peer."""
    channel = f"virtual:plant-test-{uuid.uuid4().hex}"
    builder = SessionBuilder(cfg, lockstep=lockstep)
    buses = [builder.bus(channel) for _ in range(len(served) + 1)]
    nodes = [builder.plant(bus, ids) for bus, ids in zip(buses, served, strict=False)]   # the last bus: the peer's
    errors: list[BaseException] = []

    def target(node: PlantNode) -> None:
        try:
            node.run(None)
        except BaseException as err:  # re-raised in the test thread
            errors.append(err)

    threads = [threading.Thread(target=target, args=(n,), name="plant-node", daemon=True) for n in nodes]
    for thread in threads:
        thread.start()
    try:
        yield nodes, Peer(buses[-1], tuple(sorted({n for ids in served for n in ids})))
    finally:
        for node in nodes:
            node.stop()
        for thread in threads:
            thread.join(timeout=5.0)
        builder.close()
    assert not any(t.is_alive() for t in threads), "PlantNode.run did not return after stop()"
    assert not errors, f"PlantNode.run raised {errors[0]!r}"


@contextmanager
def running_node(cfg: SeaHilConfig, *, lockstep: bool) -> Iterator[tuple[PlantNode, Peer]]:
    with running_plants(cfg, ((NODE,),), lockstep=lockstep) as (nodes, peer):
        yield nodes[0], peer


def is_hb(state: DriverState, flags: ErrorFlags | None = None) -> Callable[[Any], bool]:
    """Heartbeat in `state` with exactly `flags`, ignoring OVERRUN (timing of a shared test machine)."""
    return lambda f: (isinstance(f, Heartbeat) and f.state is state
                      and (flags is None or f.flags & ~ErrorFlags.OVERRUN == flags))


# ---- lockstep: open-loop step response against the pure model --------------------------------------------------
def test_lockstep_step_response_matches_pure_model() -> None:
    cfg, voltage_v, n_samples = load_config(), (2.0, 0.0), 150
    samples: dict[int, Feedback] = {}
    with running_node(cfg, lockstep=True) as (node, peer):
        def answer(fb: Any) -> bool:
            if isinstance(fb, Feedback):
                samples.setdefault(len(samples), fb)
                peer.send(VoltageCmd(NODE, voltage_v, fb.seq))
            return len(samples) >= n_samples
        peer.wait_for(answer, timeout_s=20.0)
    p, period_s = limb_params(cfg.plant), 1.0 / cfg.can.feedback_rate_hz
    x = initial_state(*cfg.plant.initial_theta_rad, 0.0, 0.0, p)
    for k in range(n_samples):
        fb = samples[k]
        assert fb.seq == k & 0xFF and fb.t_us == (k * round(period_s * 1e6)) & 0xFFFF
        assert fb.theta_rad == pytest.approx((x[0], x[1]), abs=THETA_LSB_RAD / 2 + 1e-9), f"sample {k}"
        x = advance(k * period_s, x, voltage_v, period_s, cfg.sim.substeps, p)
    moved = samples[n_samples - 1].theta_rad[0] - cfg.plant.initial_theta_rad[0]
    assert abs(moved) > 20 * THETA_LSB_RAD  # the step did move the hip
    assert node.drivers[NODE].counters.rejected_frames == 0


# ---- real time: watchdog and clear-errors -----------------------------------------------------------------------
def test_realtime_watchdog_fault_then_clear_errors_returns_to_init() -> None:
    cfg = load_config(overrides=FAST_RT)
    with running_node(cfg, lockstep=False) as (node, peer):
        peer.wait_for(is_hb(DriverState.INIT, ErrorFlags(0)), timeout_s=5.0)

        def command(frame: Any) -> None:  # answer every feedback, like the edge
            if isinstance(frame, FeedbackAngle):
                peer.send(VoltageCmd(NODE, (1.0, 0.0), frame.seq))
        peer.wait_for(is_hb(DriverState.RUNNING), timeout_s=5.0, on_frame=command)
        hb = peer.wait_for(is_hb(DriverState.FAULT), timeout_s=5.0)   # commands stopped
        assert ErrorFlags.WATCHDOG in hb.flags and node.drivers[NODE].counters.watchdog_trips == 1
        peer.send(VoltageCmd(NODE, (1.0, 0.0), 0))                      # ignored while latched
        peer.wait_for(lambda f: isinstance(f, Feedback), timeout_s=5.0)  # still publishing feedback
        peer.send(ClearErrors(NODE))
        peer.wait_for(is_hb(DriverState.INIT, ErrorFlags(0)), timeout_s=5.0)
    assert node.drivers[NODE].counters.ignored_commands >= 1
    assert node.stats.ticks > 0


# ---- malformed frames -------------------------------------------------------------------------------------------
def _frames_bad_by_construction() -> st.SearchStrategy[can.Message]:
    """Frames that must be rejected, whatever the codec does: each entry says why."""
    byte_data = st.binary(min_size=0, max_size=8)
    own_cmd = st.sampled_from(sorted(DLC_OF_CMD))
    wrong_dlc = st.tuples(own_cmd, byte_data).filter(lambda t: len(t[1]) != DLC_OF_CMD[t[0]]).map(
        lambda t: can.Message(arbitration_id=NODE << 5 | t[0], data=t[1], is_extended_id=False))
    unassigned = st.integers(0, 31).filter(lambda c: c not in DLC_OF_CMD)
    unknown_cmd = st.tuples(st.integers(0, 63), unassigned, byte_data).map(
        lambda t: can.Message(arbitration_id=t[0] << 5 | t[1], data=t[2], is_extended_id=False))
    nan_hi = struct.pack("<f", float("nan"))[2:]   # 0x7FC0: a float32 NaN's upper half, 32.704 V / 32.7 mm raw
    out_of_range = st.tuples(st.sampled_from([1, 2]), st.integers(0, 255), st.integers(30_001, 32_767),
                             st.sampled_from([1, -1]), st.booleans()).map(lambda t: can.Message(
                                 arbitration_id=NODE << 5 | t[0], is_extended_id=False,
                                 data=bytes([t[1]]) + struct.pack("<hh", *((t[3] * t[2], 0)[::1 if t[4] else -1]))))
    nan_payload = st.tuples(st.sampled_from([1, 2]), st.integers(0, 255), st.booleans()).map(lambda t: can.Message(
        arbitration_id=NODE << 5 | t[0], is_extended_id=False,
        data=bytes([t[1]]) + (nan_hi + bytes(2) if t[2] else bytes(2) + nan_hi)))
    foreign_remote = st.tuples(st.integers(2, 63), own_cmd).map(lambda t: can.Message(   # RTR: never a command
        arbitration_id=t[0] << 5 | t[1], is_remote_frame=True, is_extended_id=False))
    extended = st.integers(0, 0x1FFFFFFF).map(lambda i: can.Message(arbitration_id=i, data=b"", is_extended_id=True))
    bad_state = st.integers(4, 255).map(lambda s: can.Message(arbitration_id=NODE << 5 | 7, is_extended_id=False,
                                                              data=bytes([s]) + bytes(6)))
    return st.one_of(wrong_dlc, unknown_cmd, out_of_range, nan_payload, foreign_remote, extended, bad_state)


def _random_frames() -> st.SearchStrategy[can.Message]:
    nan_f32 = struct.pack("<f", float("nan"))
    nan_bytes = st.tuples(st.binary(max_size=4), st.integers(0, 8)).map(lambda t: (t[0] + nan_f32 + nan_f32)[:t[1]])
    ids = st.one_of(st.integers(0, 0x7FF), st.sampled_from([NODE << 5 | c for c in DLC_OF_CMD]))
    return st.builds(lambda i, d, remote, dlc_lie: can.Message(
        arbitration_id=i, data=d, is_extended_id=False, is_remote_frame=remote,
        dlc=(len(d) + 1) % 9 if dlc_lie else len(d), check=False),
        ids, st.one_of(st.binary(max_size=8), nan_bytes), st.booleans(), st.booleans())


def _addressed_to_another_node(msg: can.Message) -> bool:
    """The test's own statement of the acceptance filter: a data frame (classic or FD) with a DBC command id of node
    2..63."""
    plain = not (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame)
    return plain and 2 <= msg.arbitration_id >> 5 <= 63 and msg.arbitration_id & 0x1F in DLC_OF_CMD


@pytest.fixture(scope="module")
def idle_node() -> Iterator[PlantNode]:
    bus = open_bus(f"virtual:plant-test-{uuid.uuid4().hex}")
    yield PlantNode(load_config(overrides=FAST_RT), bus, (NODE,))
    bus.shutdown()


@pytest.fixture(scope="module")
def oracle() -> SeaCodec:
    return SeaCodec([NODE])


def _rejected(node: PlantNode) -> int:
    return node.drivers[NODE].counters.rejected_frames


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(msg=_frames_bad_by_construction())
def test_malformed_frames_rejected_and_counted(idle_node: PlantNode, msg: can.Message) -> None:
    before, state = _rejected(idle_node), idle_node.drivers[NODE].state
    idle_node._on_message(msg, time.monotonic_ns())
    assert _rejected(idle_node) == before + 1
    assert idle_node.drivers[NODE].state is state and ErrorFlags.BAD_FRAME in idle_node.drivers[NODE].flags


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(msg=_random_frames())
def test_random_frames_never_crash_and_count_exactly_the_rejects(idle_node: PlantNode, oracle: SeaCodec,
                                                                msg: can.Message) -> None:
    before, foreign_before = _rejected(idle_node), idle_node.stats.foreign_frames
    foreign = _addressed_to_another_node(msg)
    try:
        expected = 0 if isinstance(oracle.decode(msg), ClearErrors) else before  # CLEAR_ERRORS resets the count
    except MalformedFrame:
        expected = before if foreign else before + 1
    idle_node._on_message(msg, time.monotonic_ns())
    assert _rejected(idle_node) == expected
    assert idle_node.stats.foreign_frames == foreign_before + foreign


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(node_id=st.integers(2, 63), cmd=st.sampled_from(sorted(DLC_OF_CMD)), data=st.binary(max_size=8))
def test_frames_for_other_node_ids_are_ignored_not_rejected(idle_node: PlantNode, node_id: int, cmd: int,
                                                            data: bytes) -> None:
    """Whatever the payload: the id names another driver's command/feedback, so firmware never looks at it."""
    drv = idle_node.drivers[NODE]
    before, flags, state, foreign = _rejected(idle_node), drv.flags, drv.state, idle_node.stats.foreign_frames
    idle_node._on_message(can.Message(arbitration_id=node_id << 5 | cmd, data=data, is_extended_id=False), 0)
    assert (_rejected(idle_node), drv.flags, drv.state) == (before, flags, state)
    assert idle_node.stats.foreign_frames == foreign + 1


def test_two_drivers_on_one_bus_ignore_each_other() -> None:
    """Node 1 is commanded until RUNNING; node 2 sees those commands and node 1's feedback and heartbeats."""
    other = NODE + 1
    with running_plants(load_config(overrides=FAST_RT), ((NODE,), (other,)), lockstep=False) as (nodes, peer):
        def command(frame: Any) -> None:
            if isinstance(frame, FeedbackAngle) and frame.node_id == NODE:
                peer.send(VoltageCmd(NODE, (1.0, 0.0), frame.seq))
        peer.wait_for(lambda f: is_hb(DriverState.RUNNING)(f) and f.node_id == NODE, timeout_s=5.0, on_frame=command)
        hb = peer.wait_for(lambda f: isinstance(f, Heartbeat) and f.node_id == other, timeout_s=5.0,
                           on_frame=command)
        assert hb.rejected_frames == 0 and ErrorFlags.BAD_FRAME not in hb.flags and hb.state is DriverState.INIT
    one, two = nodes
    assert two.drivers[other].counters.rejected_frames == 0 and one.drivers[NODE].counters.rejected_frames == 0
    assert two.stats.foreign_frames > 0 and one.stats.foreign_frames > 0   # each saw the other's traffic


def test_node_still_accepts_commands_after_garbage(idle_node: PlantNode) -> None:
    drv, codec = idle_node.drivers[NODE], SeaCodec([NODE])
    idle_node._on_message(codec.encode(ClearErrors(NODE)), 0)
    idle_node._on_message(codec.encode(VoltageCmd(NODE, (1.5, -1.5), 7)), 1)
    assert drv.state is DriverState.RUNNING and drv.voltage_v == (1.5, -1.5)


def test_malformed_frames_over_the_bus_are_counted_in_heartbeat() -> None:
    bad = [can.Message(arbitration_id=NODE << 5 | 1, data=b"\x00\x01", is_extended_id=False),       # short DLC
           can.Message(arbitration_id=NODE << 5 | 1, data=b"\x00" + struct.pack("<hh", 31_000, 0),
                       is_extended_id=False),                                                          # > 30 V
           can.Message(arbitration_id=NODE << 5 | 20, data=b"\x00", is_extended_id=False),           # unknown id
           can.Message(arbitration_id=NODE << 5 | 2, data=b"\x00" + struct.pack("<f", float("nan")),
                       is_extended_id=False)]                                                          # NaN bytes
    with running_node(load_config(overrides=FAST_RT), lockstep=False) as (node, peer):
        peer.wait_for(is_hb(DriverState.INIT), timeout_s=5.0)
        for msg in bad:
            peer.bus.send(msg)
        hb = peer.wait_for(lambda f: isinstance(f, Heartbeat) and f.rejected_frames == len(bad), timeout_s=5.0)
        assert ErrorFlags.BAD_FRAME in hb.flags and hb.state is DriverState.INIT
        peer.send(VoltageCmd(NODE, (1.0, 0.0), 0))  # still answers: a valid command is taken
        peer.wait_for(is_hb(DriverState.RUNNING), timeout_s=5.0)
    assert node.drivers[NODE].counters.rejected_frames == len(bad)


class _FailingBus:
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise can.CanOperationError("interface down")


def test_send_failure_is_counted_and_flagged_not_raised(idle_node: PlantNode) -> None:
    bus, idle_node.bus = idle_node.bus, _FailingBus()
    try:
        idle_node.heartbeats()
    finally:
        idle_node.bus = bus
    assert idle_node.stats.send_failures == 1 and ErrorFlags.BUS_ERROR in idle_node.drivers[NODE].flags

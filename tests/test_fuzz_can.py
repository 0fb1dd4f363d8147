"""Fuzzing the CAN frame handlers of the driver node (`PlantNode._on_message`) and the edge (`EdgeNode.on_can`)
with hypothesis-generated frames: malformed by construction (unknown command, wrong DLC, reserved bits,
NaN/out-of-range values, bad enums, extended/remote/error/FD frames) mixed with arbitrary frames and, for the edge,
valid feedback samples with extreme values, out-of-order or partial. The node never raises, each malformed frame is
counted once (driver: counters and heartbeat BAD_FRAME flag; edge: `rejected_frames`), and a valid command /
feedback afterwards is still handled."""
from __future__ import annotations

import struct
import time
import uuid
from collections.abc import Callable

import can
from fuzz_budget import cases
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sea_hil.config.loader import load_config
from sea_hil.controller.edge_core import EdgeCore, FreeRunning
from sea_hil.errors import MalformedFrame
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import ClearErrors, DriverState, ErrorFlags, Feedback, VoltageCmd
from sea_hil.protocol.canbus import open_bus
from sea_hil.protocol.payloads import SetpointPayload, TriggerReason, encode

CASES = cases(10_000)   # tests/fuzz_budget.py: SEA_HIL_FUZZ_SCALE=1 for the depth of docs/reliability.md
NODE = 1
CMD_IDS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 31)      # includes unused command ids


@st.composite
def frames(draw: st.DrawFn) -> can.Message:
    kind = draw(st.integers(0, 3))
    if kind == 0:   # arbitrary
        ext = draw(st.booleans())
        return can.Message(arbitration_id=draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF)), is_extended_id=ext,
                           data=draw(st.binary(max_size=8)))
    if kind == 1:   # addressed to this node, any command, any length
        return can.Message(arbitration_id=NODE << 5 | draw(st.sampled_from(CMD_IDS)), is_extended_id=False,
                           data=draw(st.binary(max_size=8)))
    if kind == 2:   # voltage command with poisoned values (NaN, inf, huge float32)
        poison = draw(st.sampled_from([float("nan"), float("inf"), -float("inf"), 3e38, -1e30]))
        good = draw(st.floats(-24, 24, width=32))
        v = (poison, good) if draw(st.booleans()) else (good, poison)
        return can.Message(arbitration_id=NODE << 5 | 1, is_extended_id=False, data=struct.pack("<ff", *v))
    flag = draw(st.sampled_from(["remote", "error", "fd"]))
    return can.Message(arbitration_id=NODE << 5 | 1, is_extended_id=False, data=draw(st.binary(max_size=8)),
                       is_remote_frame=flag == "remote", is_error_frame=flag == "error", is_fd=flag == "fd")


def _for_another_driver(msg: can.Message, cmd_ids: frozenset[int]) -> bool:
    """A data frame (classic or FD) with a DBC command id of node 2..63: ignored like drive firmware's id filter."""
    plain = not (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame)
    return plain and 2 <= msg.arbitration_id >> 5 <= 63 and msg.arbitration_id & 0x1F in cmd_ids


def test_driver_frame_handler_survives_counts_and_still_obeys() -> None:
    cfg = load_config()
    bus = open_bus(f"virtual:fuzzcan-{uuid.uuid4().hex[:8]}")
    node = PlantNode(cfg, bus, (NODE,))
    drv = node.drivers[NODE]
    oracle = SeaCodec([NODE])
    cmd_ids = frozenset(m.frame_id & 0x1F for m in load_database().messages)
    seen = {"n": 0, "malformed": 0, "since_clear": 0, "t": 0}
    try:
        @settings(max_examples=CASES, deadline=None, database=None, derandomize=True,
                  suppress_health_check=[HealthCheck.too_slow])
        @given(msg=frames())
        def run(msg: can.Message) -> None:
            seen["t"] += 1000
            before = drv.counters.rejected_frames
            node._on_message(msg, seen["t"])
            seen["n"] += 1
            try:
                frame = oracle.decode(msg)
            except MalformedFrame:
                if _for_another_driver(msg, cmd_ids):   # neither a reject nor a flag
                    assert drv.counters.rejected_frames == before
                    return
                seen["malformed"] += 1
                seen["since_clear"] += 1
                assert drv.counters.rejected_frames == before + 1 and ErrorFlags.BAD_FRAME in drv.flags
                return
            if isinstance(frame, ClearErrors):
                seen["since_clear"] = 0
            assert drv.counters.rejected_frames == (0 if isinstance(frame, ClearErrors) else before)
        run()
        hb = drv.heartbeat()
        assert seen["n"] >= CASES and seen["malformed"] > CASES // 2
        assert hb.rejected_frames == min(seen["since_clear"], 0xFFFF)
        assert (ErrorFlags.BAD_FRAME in hb.flags) == (seen["since_clear"] > 0)
        node._on_message(oracle.encode(ClearErrors(NODE)), seen["t"] + 1)
        node._on_message(oracle.encode(VoltageCmd(NODE, (1.5, -2.0), 0)), seen["t"] + 2)
        assert drv.state is DriverState.RUNNING and drv.voltage_v == (1.5, -2.0)
        print(f"\ndriver: {seen['n']} frames, {seen['malformed']} malformed and counted")
    finally:
        bus.shutdown()


EDGE_CASES = cases(15_000)
_VALUES = st.floats(-1e30, 1e30, allow_nan=False) | st.sampled_from([0.0, 1e-3, -0.5, 3.0, 1e6])
_PAIRS = st.tuples(_VALUES, _VALUES)


@st.composite
def edge_input(draw: st.DrawFn, codec: SeaCodec, edge_t_us: Callable[[], int]) -> list[can.Message]:
    """Mostly one `frames()` frame; otherwise a feedback sample (saturated into the DBC ranges, any seq; its time
    any t_us or, mostly, up to 20 ms after the edge's newest sample) whose frames come shuffled, partial or with
    one corrupted."""
    if draw(st.integers(0, 7)) > 0:
        return [draw(frames())]
    t_us = draw(st.integers(0, 0xFFFF)) if draw(st.integers(0, 3)) == 0 else edge_t_us() + draw(st.integers(1, 20_000))
    fb = Feedback(NODE, draw(st.integers(0, 255)), t_us & 0xFFFF, draw(_PAIRS), draw(_PAIRS), draw(_PAIRS),
                  draw(_PAIRS))
    msgs = draw(st.permutations(codec.encode_feedback(fb, saturate=True)))
    msgs = msgs[:draw(st.sampled_from((1, 2, 3, 3, 3, 3)))]
    if draw(st.integers(0, 2)) == 0:
        i = draw(st.integers(0, len(msgs) - 1))
        msgs[i] = can.Message(arbitration_id=msgs[i].arbitration_id, is_extended_id=False,
                              data=draw(st.binary(max_size=8)))
    return msgs


def _fresh_setpoint(core: EdgeCore) -> None:
    seq = (core.intake.sp_seq.last or 0) + 1
    assert core.on_downlink(encode(SetpointPayload(seq, 0, 0, (1e-3, 0.0), (0.0, 0.0), TriggerReason.TIME)))


def test_edge_frame_handler_survives_counts_and_still_commands() -> None:
    """The edge core's CAN input (no bus, no Zenoh session): frames in, the frames it answers with out."""
    core, clock = EdgeCore(load_config(), NODE), FreeRunning()
    oracle = SeaCodec([NODE])
    seen = {"frames": 0, "malformed": 0, "samples": 0}
    sent: list[can.Message] = []

    def on_can(msg: can.Message, rx_ns: int) -> None:
        fb = core.on_frame(msg)
        if fb is not None:
            sent.extend(core.on_feedback(fb, rx_ns, clock) or ())

    _fresh_setpoint(core)

    @settings(max_examples=EDGE_CASES, deadline=None, database=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow])
    @given(msgs=edge_input(oracle, lambda: core.t_us_full))
    def run(msgs: list[can.Message]) -> None:
        for msg in msgs:
            before, samples = core.counters.rejected_frames, core.counters.feedback
            on_can(msg, time.monotonic_ns())
            seen["frames"] += 1
            seen["samples"] += core.counters.feedback - samples
            try:
                oracle.decode(msg)
            except MalformedFrame:
                seen["malformed"] += 1
                assert core.counters.rejected_frames == before + 1
                continue
            assert core.counters.rejected_frames == before
    run()
    stats = core.stats()
    assert seen["malformed"] >= EDGE_CASES * 2 // 3 and stats["rejected_frames"] == seen["malformed"]
    assert seen["samples"] > EDGE_CASES // 150 and stats["feedback_samples"] == seen["samples"]
    assert all(isinstance(oracle.decode(m), (VoltageCmd, ClearErrors)) for m in sent)   # within the DBC
    _fresh_setpoint(core)
    sent.clear()                        # forget what the fuzzing made the edge send
    last = core.counters.feedback
    t_us = (core.t_us_full + 1000) & 0xFFFF   # the sample after the newest one seen
    for msg in oracle.encode_feedback(Feedback(NODE, 200, t_us, (0.1, 0.2), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))):
        on_can(msg, 0)
    assert core.counters.feedback == last + 1
    cmds = [f for f in map(oracle.decode, sent) if isinstance(f, VoltageCmd)]
    assert [c.seq for c in cmds] == [200]
    print(f"\nedge: {seen['frames']} frames, {seen['malformed']} malformed and counted, "
          f"{seen['samples']} feedback samples handled, {len(sent)} commands")

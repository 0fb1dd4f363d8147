"""Fuzzing the driver node's CAN frame handler (`PlantNode._on_message`) with 10,000 hypothesis-generated frames:
malformed by construction (unknown command, wrong DLC, reserved bits, NaN/out-of-range values, bad enums,
extended/remote/error/FD frames) mixed with arbitrary frames. The node never raises, each malformed frame is counted
once in the driver's counters and heartbeat (BAD_FRAME flag), and a valid command afterwards is still obeyed."""
from __future__ import annotations

import struct
import uuid

import can
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plant_emulator.node import PlantNode
from protocol.can_codec import ClearErrors, DriverState, ErrorFlags, SeaCodec, VoltageCmd
from protocol.canbus import open_bus
from protocol.config import load_config
from protocol.errors import MalformedFrame

CASES = 10_000
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


def test_driver_frame_handler_survives_counts_and_still_obeys() -> None:
    cfg = load_config()
    bus = open_bus(f"virtual:fuzzcan-{uuid.uuid4().hex[:8]}")
    node = PlantNode(cfg, bus, (NODE,))
    drv = node.drivers[NODE]
    oracle = SeaCodec([NODE])
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

"""The lockstep hot path's shortcuts give exactly what the plain paths give: the plant's compiled `advance`, the
codec's fused encode checks and decode range checks, and the virtual bus's direct per-receiver copy."""
from __future__ import annotations

from typing import Any

import can
import pytest
from cantools.database import DecodeError, EncodeError
from hypothesis import given, settings
from hypothesis import strategies as st

from sea_hil.config.loader import load_config
from sea_hil.dynamics import initial_state
from sea_hil.errors import MalformedFrame
from sea_hil.jit import loaded
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.integrator import advance, make_advance_kernel, prepare_advance, rk4_step
from sea_hil.protocol import can_codec
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import FeedbackAngle, FeedbackJoint1, Heartbeat, VoltageCmd
from sea_hil.protocol.canbus import FastVirtualBus, open_bus

CODEC = SeaCodec()


def _reference_advance(t, x, u, dt, substeps, p, dist):  # type: ignore[no-untyped-def]
    h = dt / substeps
    for i in range(substeps):
        x = rk4_step(t + i * h, x, u, h, p, dist)
    return x


@pytest.mark.parametrize("kind", ["none", "sine", "noise"])
def test_prepared_advance_is_the_plain_rk4_bit_for_bit(kind: str) -> None:
    pytest.importorskip("numba")
    cfg = load_config(overrides={"disturbance": {"kind": kind, "amplitude_nm": [1.5, -0.7], "noise_hold_s": 0.0007}})
    p, dist = limb_params(cfg.plant), make_disturbance(cfg.disturbance)
    assert prepare_advance(p) and loaded(make_advance_kernel) is not None
    for substeps in (1, 2, 3):
        fast = ref = plain = initial_state(0.3, 0.6, 0.0, 0.0, p)
        for k in range(400):
            u = ((k % 37) * 0.6 - 10.0, (k % 11) * 1.1 - 5.0)
            fast = advance(k * 1e-3, fast, u, 1e-3, substeps, p, dist)
            plain = advance(k * 1e-3, plain, u, 1e-3, substeps, p, dist, jit=False)
            ref = _reference_advance(k * 1e-3, ref, u, 1e-3, substeps, p, dist)
            assert fast == ref == plain
        assert all(type(v) is float for v in fast) and fast != initial_state(0.3, 0.6, 0.0, 0.0, p)


def test_an_unprepared_kernel_is_not_used() -> None:
    def factory(fingerprint: str = "") -> Any:
        def kernel(a):  # type: ignore[no-untyped-def]
            fingerprint  # noqa: B018
            return a
        return kernel

    assert loaded(factory) is None   # never ran: a hot loop would run the plain body, not stall on a first call


def _reference_encode(codec: SeaCodec, obj: Any, saturate: bool) -> bytes:
    """clamp everything, check everything, then cantools strict: the unfused sequence of the same checks."""
    lay = codec._layout_of(type(obj))
    try:
        values = obj.to_signals()
        if saturate:
            can_codec._clamp(lay, values)
        for s in lay.sigs:
            can_codec._check_encodable(s, values[s.name])
        return lay.message.encode(values, strict=True)
    except (EncodeError, TypeError, ValueError, OverflowError, KeyError) as err:
        raise MalformedFrame(str(err)) from None


_values = st.one_of(st.floats(-80.0, 80.0), st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(-300, 70000), st.booleans(), st.just("1.0"))


@settings(max_examples=400, deadline=None)
@given(st.one_of(
    st.builds(VoltageCmd, st.just(1), st.tuples(_values, _values), _values),
    st.builds(FeedbackAngle, st.just(2), _values, _values, st.tuples(_values, _values)),
    st.builds(FeedbackJoint1, st.just(3), _values, _values, _values, _values),
    st.builds(Heartbeat, st.just(4), st.sampled_from([0, 1, 2, 3]), st.just(0), _values, _values, _values)),
    st.booleans())
def test_fused_encode_checks_match_the_unfused_sequence(obj: Any, saturate: bool) -> None:
    try:
        expected: bytes | None = _reference_encode(CODEC, obj, saturate)
    except MalformedFrame:
        expected = None
    if expected is None:
        with pytest.raises(MalformedFrame):
            CODEC.encode(obj, saturate=saturate)
    else:
        assert bytes(CODEC.encode(obj, saturate=saturate).data) == expected


@settings(max_examples=600, deadline=None)
@given(st.sampled_from(sorted(CODEC._by_cmd)), st.integers(1, 63), st.binary(min_size=8, max_size=8))
def test_decode_range_shortcut_matches_the_full_check(cmd_id: int, node_id: int, raw: bytes) -> None:
    lay = CODEC._by_cmd[cmd_id]
    can_id, dlc, data = node_id << can_codec.CMD_BITS | cmd_id, lay.dlc, raw[:lay.dlc]
    try:
        got: Any = CODEC.decode_raw(can_id, data, dlc)
    except MalformedFrame:
        got = None
    try:
        if int.from_bytes(data, "little") & ~lay.used_mask:
            raise MalformedFrame("reserved bits")
        decoded = lay.message.decode(data, decode_choices=False, allow_excess=False)
        values = {s.name: can_codec._checked(lay.message.name, s, decoded[s.name]) for s in lay.sigs}
        expected: Any = lay.cls.from_signals(node_id, values)
    except (MalformedFrame, DecodeError, ValueError):
        expected = None
    assert got == expected


def test_fast_virtual_bus_gives_every_receiver_its_own_copy() -> None:
    a, b, c = open_bus("virtual:hotpath-copy"), open_bus("virtual:hotpath-copy"), open_bus("virtual:hotpath-copy")
    plain = can.Bus(interface="virtual", channel="hotpath-copy")   # python-can's own class on the same channel
    try:
        assert isinstance(a, FastVirtualBus)
        sent = can.Message(arbitration_id=0x25, data=bytes(range(8)), is_extended_id=False, timestamp=1.0)
        a.send(sent)
        got = [bus.recv(1.0) for bus in (b, c, plain)]
        assert all(m is not None and m is not sent for m in got)
        assert len({id(m) for m in got}) == 3 and len({id(m.data) for m in got}) == 3
        got[0].data[0] = 0xFF
        assert got[1].data == bytearray(range(8)) and got[1].is_rx and got[1].channel == "hotpath-copy"
        assert got[1].timestamp != 1.0 and not got[1].is_extended_id and got[1].dlc == 8
        assert a.recv(0) is None                         # not its own messages
        plain.send(can.Message(arbitration_id=0x45, data=b"\x01", is_extended_id=False))
        assert b.recv(1.0).arbitration_id == 0x45 and c.recv(1.0).data == bytearray(b"\x01")
    finally:
        for bus in (a, b, c, plain):
            bus.shutdown()


def test_fast_virtual_bus_keeps_the_order_and_the_own_message_option() -> None:
    a = FastVirtualBus(channel="hotpath-order", receive_own_messages=True)
    b = FastVirtualBus(channel="hotpath-order", rx_queue_size=2)   # bounded: python-can's dropping queue kept
    try:
        for i in range(2):
            a.send(can.Message(arbitration_id=i, is_extended_id=False))
        with pytest.raises(can.CanOperationError):   # b's queue is full: reported as python-can does
            a.send(can.Message(arbitration_id=2, is_extended_id=False), timeout=0.001)
        assert [a.recv(0).arbitration_id for _ in range(3)] == [0, 1, 2] and a.recv(0) is None
        assert [b.recv(0).arbitration_id for _ in range(2)] == [0, 1] and b.recv(0) is None
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.parametrize("fields", [
    {"arbitration_id": 0x25, "data": bytes(range(8)), "is_extended_id": False},
    {"arbitration_id": 0x1ABCDE, "data": bytearray(b"\x01\x02"), "is_extended_id": True, "dlc": 2},
    {"arbitration_id": 0x31, "is_remote_frame": True, "dlc": 4, "is_extended_id": False},
    {"arbitration_id": 0x32, "is_error_frame": True, "is_extended_id": False, "data": b"\x00"},
    {"arbitration_id": 0x33, "data": bytes(64), "is_fd": True, "bitrate_switch": True,
     "error_state_indicator": True, "is_extended_id": False}])
@pytest.mark.parametrize("is_rx", [True, False])
def test_received_copy_equals_the_constructors_copy(fields: dict, is_rx: bool) -> None:
    from sea_hil.protocol.canbus import received_copy
    msg = can.Message(timestamp=3.0, channel="sender", **fields)
    fast = received_copy(msg, 7.5, "chan", is_rx)
    slow = can.Message(timestamp=7.5, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                       is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame, channel="chan",
                       dlc=msg.dlc, data=bytearray(msg.data), is_fd=msg.is_fd, is_rx=is_rx,
                       bitrate_switch=msg.bitrate_switch, error_state_indicator=msg.error_state_indicator)
    slots = [s for s in can.Message.__slots__ if s != "__weakref__"]
    assert {s: getattr(fast, s) for s in slots} == {s: getattr(slow, s) for s in slots}
    assert type(fast.data) is bytearray and fast.data is not msg.data


@pytest.mark.parametrize("is_fd,brs", [(False, False), (True, True), (True, False)])
def test_new_message_equals_the_constructors_message(is_fd: bool, brs: bool) -> None:
    from sea_hil.protocol.can_codec import new_message
    data = bytes(range(64 if is_fd else 8))
    fast = new_message(0x123, data, is_fd, brs)
    slow = can.Message(arbitration_id=0x123, data=data, is_extended_id=False, is_fd=is_fd, bitrate_switch=brs)
    slow.data = data
    slots = [s for s in can.Message.__slots__ if s != "__weakref__"]
    assert {s: getattr(fast, s) for s in slots} == {s: getattr(slow, s) for s in slots}
    assert fast.data is data


"""Tests of protocol/sea.dbc + protocol/can_codec.py (bit layout in docs/can-protocol.md)."""
from __future__ import annotations

import math
import random
import subprocess
import sys
from pathlib import Path

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import (
    FEEDBACK_PARTS,
    FRAME_TYPES,
    SEQ_MODULUS,
    T_US_MODULUS,
    ClearErrors,
    DeflectionSetpoint,
    DriverState,
    ErrorFlags,
    EStop,
    Feedback,
    FeedbackAngle,
    FeedbackJoint1,
    FeedbackJoint2,
    Heartbeat,
    VoltageCmd,
)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def codec() -> SeaCodec:
    return SeaCodec()


def _msg(can_id: int, data: bytes | str, **kw) -> can.Message:
    payload = bytes.fromhex(data) if isinstance(data, str) else data
    return can.Message(arbitration_id=can_id, data=payload, is_extended_id=False, **kw)


# Expected bytes computed by hand from the layout (little-endian, LSB first, two's complement):
EXACT = [
    (EStop(1), 0x020, ""),                                                   # node 1 << 5 | cmd 0, DLC 0
    (ClearErrors(5), 0x0A6, ""),                                             # 5 << 5 | 6 = 0xA6
    # seq 200 = C8; 12.345 V / 1 mV = 12345 = 0x3039; -3.2 V -> -3200 = 0xF380
    (VoltageCmd(1, (12.345, -3.2), 200), 0x021, "c8 3930 80f3"),
    # 0.0125 m / 1 um = 12500 = 0x30D4; -1 um -> -1 = 0xFFFF
    (DeflectionSetpoint(2, (0.0125, -0.000001), 0), 0x042, "00 d430 ffff"),
    # 63 << 5 | 7; state FAULT=2; flags (u16) WATCHDOG(bit0)|BUS_ERROR(bit4)|FORCE_LIMIT(bit8) = 0x0111; 258 = 0x0102;
    # 65535; seq 17 = 0x11
    (Heartbeat(63, DriverState.FAULT, ErrorFlags.WATCHDOG | ErrorFlags.BUS_ERROR | ErrorFlags.FORCE_LIMIT, 258, 65535,
               17), 0x7E7, "02 1101 0201 ffff 11"),
    # seq 5 | t_us 0xBEEF at bit 8 | theta1 bits 24..43 = 1.5708 rad / 1e-5 = 157080 | theta2 bits 44..63 = -1e-5
    # rad -> -1 -> 2^20 - 1; as one little-endian 64-bit integer:
    (FeedbackAngle(1, 5, 0xBEEF, (1.5708, -0.00001)), 0x023,
     (5 | 0xBEEF << 8 | 157080 << 24 | (2**20 - 1) << 44).to_bytes(8, "little").hex()),
    # seq 5 | omega1 bits 8..25 = 1 rad/s / 2.5e-4 = 4000 | delta1 bits 26..44 = 0.03 m / 1.25e-7 = 240000
    # | nut_vel1 bits 45..63 = -0.6 m/s / 2.5e-6 = -240000 -> 2^19 - 240000 = 284288
    (FeedbackJoint1(1, 5, 1.0, 0.03, -0.6), 0x024,
     (5 | 4000 << 8 | 240000 << 26 | 284288 << 45).to_bytes(8, "little").hex()),
    # seq 6 | omega2 = -30 rad/s -> -120000 -> 2^18 - 120000 = 142144 | delta2 = -1.25e-7 m -> 2^19 - 1
    # | nut_vel2 = 2.5e-6 m/s -> 1
    (FeedbackJoint2(2, 6, -30.0, -0.000000125, 0.0000025), 0x045,
     (6 | 142144 << 8 | (2**19 - 1) << 26 | 1 << 45).to_bytes(8, "little").hex()),
]


@pytest.mark.parametrize("obj,can_id,hexdata", EXACT, ids=[type(e[0]).__name__ for e in EXACT])
def test_exact_bytes_and_round_trip(codec: SeaCodec, obj, can_id: int, hexdata: str) -> None:
    msg = codec.encode(obj)
    assert (msg.arbitration_id, msg.is_extended_id, msg.dlc) == (can_id, False, len(bytes.fromhex(hexdata)))
    assert bytes(msg.data) == bytes.fromhex(hexdata)
    back = codec.decode(_msg(can_id, hexdata))
    assert type(back) is type(obj)
    for name, val in vars(obj).items():
        got = getattr(back, name)
        if isinstance(val, (tuple, float)):
            assert got == pytest.approx(val, abs=1e-12)
        else:
            assert got == val


def test_every_frame_type_covered_and_ids_unique(codec: SeaCodec) -> None:
    assert {type(e[0]) for e in EXACT} == set(FRAME_TYPES) - {Feedback}   # Feedback: tests/test_can_fd.py
    ids = [e[1] & 0x1F for e in EXACT]
    assert len(set(ids)) == len(ids)
    assert codec.encode(EStop(3)).arbitration_id == 0x060                  # node 3 << 5 | cmd 0


def test_dbc_meets_required_ranges_and_resolutions() -> None:
    db = load_database()
    need = {  # signal: (required |range|, required resolution)
        "voltage1": (30, 1e-3), "vx1": (0.03, 1e-6), "theta1": (3.2, 1e-5), "omega1": (30, 2.5e-4),
        "delta1": (0.03, 1.25e-7), "nut_vel1": (0.6, 2.5e-6),
    }
    sigs = {s.name: s for m in db.messages for s in m.signals}
    for name, (rng, res) in need.items():
        for s in (sigs[name], sigs[name[:-1] + "2"]):
            assert s.scale <= res * (1 + 1e-9), s.name
            assert s.minimum <= -rng and s.maximum >= rng, s.name
            raw_max = (1 << (s.length - 1)) - 1
            assert raw_max * s.scale >= s.maximum and -(raw_max + 1) * s.scale <= s.minimum, s.name
    assert all(m.length <= (64 if m.is_fd else 8) for m in db.messages)


def test_python_enums_match_dbc() -> None:
    db = load_database()
    hb = db.get_message_by_name("HEARTBEAT")
    assert {int(k): str(v) for k, v in hb.get_signal_by_name("state").choices.items()} == \
        {s.value: s.name for s in DriverState}
    flag_bits = {s.name: s.start - 8 for s in hb.signals if s.name.startswith("err_")}
    assert flag_bits == {"err_" + f.name.lower(): int(f).bit_length() - 1 for f in ErrorFlags}
    lengths = {s.name: s.length for m in db.messages for s in m.signals}
    assert (1 << lengths["t_us"], 1 << lengths["seq"]) == (T_US_MODULUS, SEQ_MODULUS)


BAD_ENCODE = [
    VoltageCmd(1, (30.001, 0.0), 0), VoltageCmd(1, (0.0, -30.001), 0), VoltageCmd(1, (math.nan, 0.0), 0),
    VoltageCmd(1, (math.inf, 0.0), 0), VoltageCmd(1, (0.0, 0.0), 256), VoltageCmd(1, (0.0, 0.0), -1),
    VoltageCmd(1, (0.0, 0.0), 1.5), VoltageCmd(1, (0.0,), 1), VoltageCmd(1, "ab", 1),  # type: ignore[arg-type]
    VoltageCmd(0, (0.0, 0.0), 1), VoltageCmd(64, (0.0, 0.0), 1), DeflectionSetpoint(1, (0.0301, 0.0), 0),
    FeedbackAngle(1, 0, 65536, (0.0, 0.0)), FeedbackAngle(1, 0, 0, (3.2001, 0.0)),
    FeedbackJoint1(1, 0, 30.01, 0.0, 0.0), FeedbackJoint2(1, 0, 0.0, 0.0, -0.6002),
    FeedbackJoint2(1, 0, 0.0, math.nan, 0.0), FeedbackJoint1(1, 0, 0.0, 0.0301, 0.0),
    Heartbeat(1, 7, ErrorFlags(0), 0, 0, 0),  # type: ignore[arg-type]
    Heartbeat(1, DriverState.RUNNING, 512, 0, 0, 0),  # type: ignore[arg-type]
    Heartbeat(1, DriverState.RUNNING, ErrorFlags(0), 65536, 0, 0),
]


@pytest.mark.parametrize("obj", BAD_ENCODE, ids=range(len(BAD_ENCODE)))
def test_strict_encoding_rejects(codec: SeaCodec, obj) -> None:
    with pytest.raises(MalformedFrame):
        codec.encode(obj)


def test_encode_rejects_foreign_type(codec: SeaCodec) -> None:
    with pytest.raises(MalformedFrame, match="not a sea-hil CAN frame"):
        codec.encode(Feedback(1, 0, 0, (0, 0), (0, 0), (0, 0), (0, 0)))  # type: ignore[arg-type]


BAD_DECODE = [
    ("unknown CAN id", _msg(0x02B, "")),                           # node 1, cmd 11 unused
    ("CAN FD profile", _msg(0x028, bytes(8))),                     # VOLTAGE_CMD_FD: not in the classic profile
    ("unknown CAN id", _msg(0x001, "00 0000 0000")),               # node 0 does not exist
    ("DLC", _msg(0x021, "00 0000 00")),
    ("DLC", _msg(0x021, "00 0000 0000 00")),
    ("DLC", _msg(0x020, "00")),
    ("DLC", can.Message(arbitration_id=0x021, data=bytes(5), dlc=6, is_extended_id=False)),
    ("remote", can.Message(arbitration_id=0x021, is_remote_frame=True, dlc=5, is_extended_id=False)),
    ("error", can.Message(arbitration_id=0x021, is_error_frame=True, data=bytes(5), is_extended_id=False)),
    ("extended", can.Message(arbitration_id=0x021, data=bytes(5), is_extended_id=True)),
    ("FD", can.Message(arbitration_id=0x021, data=bytes(5), is_extended_id=False, is_fd=True)),
    ("outside", _msg(0x021, "00 3175 0000")),                      # 30001 mV > 30 V
    ("outside", _msg(0x023, (320001 << 24).to_bytes(8, "little").hex())),  # theta1 raw 320001 > 3.2 rad
    ("enum", _msg(0x027, "04 0000 0000 0000 00")),                 # state 4
    ("reserved", _msg(0x027, "01 0002 0000 0000 00")),             # flag bit 9 reserved
    ("DLC", _msg(0x027, "01 00 0000 0000 00")),                    # the 7-byte heartbeat of DBC version 1
]


@pytest.mark.parametrize("reason,msg", BAD_DECODE, ids=[f"{i}-{r}" for i, (r, _) in enumerate(BAD_DECODE)])
def test_decode_rejects(codec: SeaCodec, reason: str, msg: can.Message) -> None:
    with pytest.raises(MalformedFrame, match=reason):
        codec.decode(msg)


def test_node_filter() -> None:
    only2 = SeaCodec(node_ids=[2])
    assert only2.decode(_msg(0x040, "")) == EStop(2)
    with pytest.raises(MalformedFrame, match="node 1, which is not served"):
        only2.decode(_msg(0x020, ""))
    with pytest.raises(MalformedFrame):
        SeaCodec(node_ids=[0])


_KNOWN = [(e[1] & 0x1F, len(bytes.fromhex(e[2]))) for e in EXACT]


@st.composite
def _frames(draw) -> can.Message:
    kind = draw(st.sampled_from(["valid_id"] * 6 + ["any_id"] * 3 + ["remote", "error", "extended", "fd"]))
    if kind == "valid_id":  # a served id with its correct DLC, random payload: exercises the value checks
        cmd, dlc = draw(st.sampled_from(_KNOWN))
        return _msg(draw(st.integers(1, 63)) << 5 | cmd, draw(st.binary(min_size=dlc, max_size=dlc)))
    data = draw(st.binary(max_size=64 if kind == "fd" else 8))
    can_id = draw(st.integers(0, 0x1FFFFFFF if kind == "extended" else 0x7FF))
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=kind == "extended",
                       is_remote_frame=kind == "remote", is_error_frame=kind == "error", is_fd=kind == "fd")


def _check_decodes_or_rejects(codec: SeaCodec, msg: can.Message) -> bool:
    try:
        obj = codec.decode(msg)
    except MalformedFrame:
        return False
    assert type(obj) in FRAME_TYPES
    again = codec.encode(obj)  # every accepted frame is valid and re-encodes to the same bits
    assert (again.arbitration_id, bytes(again.data)) == (msg.arbitration_id, bytes(msg.data))
    return True


@settings(max_examples=1200, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=_frames())
def test_random_frames_decode_or_raise_malformed(codec: SeaCodec, msg: can.Message) -> None:
    _check_decodes_or_rejects(codec, msg)


def test_random_frames_seeded_cover_both_outcomes(codec: SeaCodec) -> None:
    rng = random.Random(1234)
    outcomes = []
    for _ in range(1500):
        cmd, dlc = rng.choice(_KNOWN)
        if rng.random() < 0.3:
            dlc = rng.randint(0, 8)
        data = bytes(rng.getrandbits(8) for _ in range(dlc))
        outcomes.append(_check_decodes_or_rejects(codec, _msg(rng.randint(0, 63) << 5 | cmd, data)))
    assert 300 < sum(outcomes) < 1200


def test_quantisation_error_bounds(codec: SeaCodec) -> None:
    rng = random.Random(7)
    half_lsb = {"voltage_v": 0.5e-3, "deflection_m": 0.5e-6, "theta_rad": 0.5e-5, "omega_rad_s": 1.25e-4,
                "delta_m": 0.625e-7, "nut_vel_m_s": 1.25e-6}

    def u(lim: float) -> tuple[float, float]:
        return (rng.uniform(-lim, lim), rng.uniform(-lim, lim))

    for _ in range(300):
        objs = [VoltageCmd(1, u(30.0), 1), DeflectionSetpoint(1, u(0.03), 1),
                *Feedback(1, 9, 77, u(3.2), u(30.0), u(0.03), u(0.6)).parts()]
        for obj in objs:
            back = codec.decode(codec.encode(obj))
            for name, bound in half_lsb.items():
                if hasattr(obj, name):
                    sent, got = getattr(obj, name), getattr(back, name)
                    pairs = zip(sent, got, strict=True) if isinstance(sent, tuple) else [(sent, got)]
                    err = max(abs(a - b) for a, b in pairs)
                    assert err <= bound * (1 + 1e-6), (name, err)


def test_saturate(codec: SeaCodec) -> None:
    cmd, changed = codec.saturate(VoltageCmd(1, (40.0, -math.inf), 3))
    assert changed and cmd == VoltageCmd(1, (30.0, -30.0), 3)
    same = VoltageCmd(1, (1.0, 2.0), 3)
    assert codec.saturate(same) == (same, False)
    hb, changed = codec.saturate(Heartbeat(1, DriverState.RUNNING, ErrorFlags(0), 70000, 3, 1))
    assert changed and hb.rejected_frames == 65535
    fb, changed = codec.saturate(Feedback(1, 2, 3, (4.0, 0.0), (0.0, -31.0), (0.0, 0.1), (0.7, 0.0)))
    assert changed and fb == Feedback(1, 2, 3, (3.2, 0.0), (0.0, -30.0), (0.0, 0.03), (0.6, 0.0))
    assert len(codec.encode_feedback(fb)) == 3
    nan_cmd, _ = codec.saturate(VoltageCmd(1, (math.nan, 0.0), 3))
    with pytest.raises(MalformedFrame, match="not finite"):
        codec.encode(nan_cmd)


def test_cantools_cli_decodes_candump_for_any_node() -> None:
    lines = "  vcan0  041   [5]  C8 39 30 80 F3\n  vcan0  047   [8]  02 11 00 02 01 FF FF 11\n"  # node 2
    out = subprocess.run([sys.executable, "-m", "cantools", "decode", "-m", "0x1F", str(ROOT / "protocol/sea.dbc")],
                         input=lines, capture_output=True, text=True, timeout=60, check=True).stdout
    assert "VOLTAGE_CMD" in out and "voltage1: 12.345 V" in out and "voltage2: -3.2 V" in out
    assert "HEARTBEAT" in out and "state: FAULT" in out and "rejected_frames: 258" in out


def test_feedback_parts_types() -> None:
    fb = Feedback(1, 1, 1001, (0.5, -0.25), (1.0, -2.0), (0.001, -0.002), (0.1, -0.2))
    assert tuple(type(p) for p in fb.parts()) == FEEDBACK_PARTS


def test_encode_with_saturate_equals_saturate_then_encode(codec: SeaCodec) -> None:
    for obj in (VoltageCmd(1, (40.0, -math.inf), 3), VoltageCmd(1, (1.0, 2.0), 4),
                Heartbeat(1, DriverState.RUNNING, ErrorFlags(0), 70000, 3, 1)):
        assert bytes(codec.encode(obj, saturate=True).data) == bytes(codec.encode(codec.saturate(obj)[0]).data)
    fb = Feedback(1, 2, 3, (4.0, 0.0), (0.0, -31.0), (0.0, 0.1), (0.7, 0.0))
    assert ([bytes(m.data) for m in codec.encode_feedback(fb, saturate=True)]
            == [bytes(m.data) for m in codec.encode_feedback(codec.saturate(fb)[0])])
    with pytest.raises(MalformedFrame):
        codec.encode(VoltageCmd(1, (math.nan, 0.0), 3), saturate=True)


def test_decode_raw_matches_decode(codec: SeaCodec) -> None:
    msg = codec.encode(VoltageCmd(3, (1.25, -0.5), 9))
    assert codec.decode_raw(0x61, bytes(msg.data), 5) == codec.decode(msg) == VoltageCmd(3, (1.25, -0.5), 9)
    for kw in ({"is_extended": True}, {"is_error": True}, {"is_remote": True}, {"is_fd": True}):
        with pytest.raises(MalformedFrame, match="not accepted"):
            codec.decode_raw(0x61, bytes(msg.data), 5, **kw)
    with pytest.raises(MalformedFrame, match="DLC"):
        codec.decode_raw(0x61, bytes(msg.data), 8)


def test_encoded_data_is_immutable_and_virtual_bus_copies_are_independent(codec: SeaCodec) -> None:
    msg = codec.encode(VoltageCmd(1, (1.0, 2.0), 5))
    assert isinstance(msg.data, bytes)
    a, b = can.Bus(interface="virtual", channel="codec-copy"), can.Bus(interface="virtual", channel="codec-copy")
    try:
        a.send(msg)
        got = b.recv(timeout=5.0)
        assert got is not None and got is not msg and bytes(got.data) == msg.data
        assert codec.decode(got) == VoltageCmd(1, (1.0, 2.0), 5)
    finally:
        a.shutdown()
        b.shutdown()

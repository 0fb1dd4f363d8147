"""The CAN FD profile of protocol/sea.dbc + protocol/can_codec.py (layout in docs/can-protocol.md, "CAN FD profile")."""
from __future__ import annotations

import math

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sea_hil.config.loader import load_config
from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import (
    DriverState,
    ErrorFlags,
    EStop,
    Feedback,
    FeedbackAngle,
    Heartbeat,
    VoltageCmd,
    profile_messages,
)


@pytest.fixture(scope="module")
def fd() -> SeaCodec:
    return SeaCodec(fd=True)


def _s24(v: int) -> int:
    return v & 0xFFFFFF


def test_dbc_marks_the_fd_messages() -> None:
    db = load_database()
    fd_msgs = {m.name: m for m in db.messages if m.is_fd}
    assert set(fd_msgs) == {"VOLTAGE_CMD_FD", "FEEDBACK_FD"}
    assert (fd_msgs["FEEDBACK_FD"].length, fd_msgs["VOLTAGE_CMD_FD"].length) == (32, 8)
    assert db.dbc.attributes["BusType"].value == "CAN FD"
    assert set(profile_messages(True).values()) == {"ESTOP", "CLEAR_ERRORS", "VOLTAGE_CMD_FD", "DEFLECTION_SETPOINT",
                                                    "HEARTBEAT", "FEEDBACK_FD"}


def test_feedback_fd_exact_bytes(fd: SeaCodec) -> None:
    fb = Feedback(1, 7, 0xBEEF, (1.5708, -1e-6), (-30.0, 5e-6), (0.03, -5e-9), (-0.6, 1e-7))
    (msg,) = fd.encode_feedback(fb)
    assert (msg.arbitration_id, msg.is_fd, msg.bitrate_switch, msg.dlc) == (0x02A, True, True, 32)
    # seq | t_us << 8 | 24-bit two's complement raws from bit 24 on, each signal 24 bits after the previous
    raws = [1570800, -1, -6000000, 1, 6000000, -1, -6000000, 1]
    want = 7 | 0xBEEF << 8
    for i, r in enumerate(raws):
        want |= _s24(r) << (24 + 24 * i)
    assert bytes(msg.data) == want.to_bytes(32, "little")
    back = fd.decode(msg)
    assert isinstance(back, Feedback) and back.seq == 7 and back.t_us == 0xBEEF
    for got, ref in zip((*back.theta_rad, *back.omega_rad_s, *back.delta_m, *back.nut_vel_m_s),
                        (*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s), strict=True):
        assert got == pytest.approx(ref, abs=1e-12)


def test_voltage_fd_exact_bytes_and_finer_resolution(fd: SeaCodec) -> None:
    msg = fd.encode(VoltageCmd(2, (12.34567, -3.2), 200))
    assert (msg.arbitration_id, msg.is_fd, msg.dlc) == (0x048, True, 8)
    assert bytes(msg.data) == (200 | 1234567 << 8 | _s24(-320000) << 32).to_bytes(8, "little")
    assert fd.decode(msg).voltage_v == pytest.approx((12.34567, -3.2), abs=1e-12)
    classic = SeaCodec()
    assert classic.decode(classic.encode(VoltageCmd(2, (12.34567, 0.0), 1))).voltage_v[0] == pytest.approx(12.346)


def test_profile_mismatch_is_a_clear_rejection(fd: SeaCodec) -> None:
    classic = SeaCodec()
    fb = Feedback(1, 1, 1, (0.1, 0.2), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))
    with pytest.raises(MalformedFrame, match="FEEDBACK_FD .* CAN FD profile; this node runs classic CAN"):
        classic.decode(fd.encode_feedback(fb)[0])
    with pytest.raises(MalformedFrame, match="FEEDBACK_ANGLE .* classic profile; this node runs CAN FD"):
        fd.decode(classic.encode_feedback(fb)[0])
    with pytest.raises(MalformedFrame, match="not a sea-hil CAN frame"):
        fd.encode(FeedbackAngle(1, 1, 1, (0.0, 0.0)))
    # the FD flag must match the message: FEEDBACK_FD's bytes in a classic frame, a heartbeat sent as FD
    good = fd.encode_feedback(fb)[0]
    with pytest.raises(MalformedFrame, match="classic frame .* not accepted"):
        fd.decode_raw(good.arbitration_id, bytes(good.data), good.dlc, is_fd=False)
    hb = fd.encode(Heartbeat(1, DriverState.RUNNING, ErrorFlags(0), 0, 0, 1))
    assert not hb.is_fd and fd.decode(hb).state is DriverState.RUNNING
    with pytest.raises(MalformedFrame, match="CAN FD frame .* not accepted"):
        fd.decode_raw(hb.arbitration_id, bytes(hb.data), hb.dlc, is_fd=True)
    with pytest.raises(MalformedFrame, match="DLC"):
        fd.decode_raw(good.arbitration_id, bytes(good.data)[:24], 24, is_fd=True)
    with pytest.raises(MalformedFrame, match="reserved"):
        fd.decode_raw(good.arbitration_id, bytes(good.data[:31]) + b"\x01", 32, is_fd=True)


def test_either_profile_codec_decodes_both(fd: SeaCodec) -> None:
    both, classic = SeaCodec(fd=None), SeaCodec()
    fb = Feedback(3, 9, 77, (0.1, 0.2), (1.0, -1.0), (0.001, -0.001), (0.01, 0.02))
    assert isinstance(both.decode(fd.encode_feedback(fb)[0]), Feedback)
    assert isinstance(both.decode(classic.encode_feedback(fb)[0]), FeedbackAngle)
    assert len(both.encode_feedback(fb)) == 3     # encodes classic
    assert both.decode(fd.encode(EStop(3))) == EStop(3)


def test_saturate_and_bitrate_switch_from_config() -> None:
    cfg = load_config(None).can
    on = SeaCodec.for_bus(cfg.model_copy(update={"fd": True}))
    off = SeaCodec.for_bus(cfg.model_copy(update={"fd": True, "data_bitrate_bps": cfg.bitrate_bps}))
    fb = Feedback(1, 2, 3, (4.0, 0.0), (0.0, -31.0), (0.0, 0.1), (0.7, math.nan))
    sat, changed = on.saturate(fb)
    assert changed and sat.theta_rad == (3.2, 0.0) and sat.omega_rad_s == (0.0, -30.0) and sat.delta_m == (0.0, 0.03)
    with pytest.raises(MalformedFrame, match="not finite"):
        on.encode_feedback(fb, saturate=True)
    ok = Feedback(1, 2, 3, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))
    assert on.encode_feedback(ok)[0].bitrate_switch and not off.encode_feedback(ok)[0].bitrate_switch
    assert not SeaCodec.for_bus(cfg).encode(VoltageCmd(1, (0.0, 0.0), 0)).is_fd


_val = st.floats(-1.0, 1.0)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.integers(1, 63), st.integers(0, 255), st.integers(0, 65535), st.tuples(*[_val] * 8))
def test_fd_feedback_round_trip_within_half_an_lsb(node: int, seq: int, t_us: int, v: tuple[float, ...]) -> None:
    fd = SeaCodec(fd=True)
    fb = Feedback(node, seq, t_us, (3 * v[0], 3 * v[1]), (29 * v[2], 29 * v[3]), (0.03 * v[4], 0.03 * v[5]),
                  (0.6 * v[6], 0.6 * v[7]))
    (msg,) = fd.encode_feedback(fb)
    back = fd.decode(can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data), is_extended_id=False,
                                 is_fd=True))
    assert (back.node_id, back.seq, back.t_us) == (node, seq, t_us)
    for got, ref, lsb in zip((*back.theta_rad, *back.omega_rad_s, *back.delta_m, *back.nut_vel_m_s),
                             (*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s),
                             (1e-6, 1e-6, 5e-6, 5e-6, 5e-9, 5e-9, 1e-7, 1e-7), strict=True):
        assert abs(got - ref) <= lsb / 2 * (1 + 1e-6)

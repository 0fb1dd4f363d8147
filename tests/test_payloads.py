"""Payload codec, counters, sequence tracking, wire-size estimate and key expressions."""
from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sea_hil.errors import ConfigError, MalformedPayload
from sea_hil.protocol.keys import Keys, any_limb
from sea_hil.protocol.payload_fields import PayloadRejected, RejectReason
from sea_hil.protocol.payloads import (
    HEADER_SIZE,
    MAGIC,
    PAYLOAD_SIZE,
    AckPayload,
    MsgType,
    PayloadCounters,
    SetpointPayload,
    StatePayload,
    TriggerReason,
    VoltagePayload,
    decode,
    encode,
)
from sea_hil.protocol.sequence import SequenceTracker, SeqVerdict
from sea_hil.protocol.wire_size import estimate_wire_bytes

finite = st.floats(allow_nan=False, allow_infinity=False)
pair = st.tuples(finite, finite)
u32 = st.integers(0, 2**32 - 1)
u64 = st.integers(0, 2**64 - 1)


def _state(**kw: object) -> StatePayload:
    base = dict(seq=7, t_ns=123, sample_t_ns=10_000_000, theta_rad=(0.1, -0.2), omega_rad_s=(1.0, 2.0),
                delta_m=(1e-4, -2e-4), nut_vel_m_s=(0.0, 0.5))
    base.update(kw)
    return StatePayload(**base)  # type: ignore[arg-type]


@given(u32, u64, u64, pair, pair, pair, pair, u64)
def test_state_roundtrip_is_bit_exact(seq, t, ts, th, om, de, nv, epoch):
    p = StatePayload(seq, t, ts, th, om, de, nv, epoch=epoch)
    b = encode(p)
    assert len(b) == PAYLOAD_SIZE[MsgType.STATE] == 96
    assert decode(b) == p


@given(u32, u64, u32, pair, pair, st.sampled_from(list(TriggerReason)))
def test_setpoint_roundtrip(seq, t, sseq, d, s, reason):
    p = SetpointPayload(seq, t, sseq, d, s, reason)
    q = decode(encode(p))
    assert q == p and isinstance(q.reason, TriggerReason) and len(encode(p)) == 61


@given(u32, u64, u32, u32, st.booleans())
def test_ack_roundtrip(seq, t, sseq, spseq, sent):
    p = AckPayload(seq, t, sseq, spseq, sent)
    assert decode(encode(p)) == p and len(encode(p)) == 33


def test_ack_flag_must_be_boolean():
    b = bytearray(encode(AckPayload(1, 2, 3, 4, True)))
    b[-1] = 2
    assert _reason(bytes(b)) is RejectReason.ENUM


@given(u32, u64, u32, pair)
def test_voltage_roundtrip(seq, t, sseq, v):
    p = VoltagePayload(seq, t, sseq, v)
    assert decode(encode(p)) == p and len(encode(p)) == 44


def _reason(b: bytes) -> RejectReason:
    with pytest.raises(MalformedPayload) as ei:
        decode(b)
    assert isinstance(ei.value, PayloadRejected)
    return ei.value.reason


def test_rejections_name_their_reason():
    good = encode(_state())
    assert _reason(good[:HEADER_SIZE - 1]) is RejectReason.LENGTH
    assert _reason(good[:-1]) is RejectReason.LENGTH
    assert _reason(good + b"\0") is RejectReason.LENGTH
    assert _reason(b"XX" + good[2:]) is RejectReason.MAGIC
    assert _reason(good[:2] + bytes([99]) + good[3:]) is RejectReason.VERSION
    assert _reason(good[:3] + bytes([200]) + good[4:]) is RejectReason.TYPE
    nan = good[:HEADER_SIZE + 8] + struct.pack("<d", math.nan) + good[HEADER_SIZE + 16:]
    assert _reason(nan) is RejectReason.NONFINITE
    sp = bytearray(encode(SetpointPayload(1, 2, 3, (0.0, 0.0), (0.0, 0.0), TriggerReason.HEARTBEAT)))
    sp[-1] = 77
    assert _reason(bytes(sp)) is RejectReason.ENUM
    assert "enum" in str(pytest.raises(MalformedPayload, decode, bytes(sp)).value)


def test_constructor_rejects_bad_values():
    with pytest.raises(MalformedPayload):
        _state(theta_rad=(math.inf, 0.0))
    with pytest.raises(MalformedPayload):
        _state(seq=2**32)
    with pytest.raises(MalformedPayload):
        VoltagePayload(1, -1, 0, (0.0, 0.0))
    with pytest.raises(MalformedPayload):
        VoltagePayload(1, 1, 0, (0.0,))  # type: ignore[arg-type]


def test_counters_count_by_reason_and_never_raise():
    c = PayloadCounters()
    assert c.try_decode(encode(_state())) == _state()
    assert c.try_decode(b"") is None
    assert c.try_decode(b"XX" + b"\0" * 86) is None
    assert c.try_decode(MAGIC + b"\0" * 86) is None  # version 0
    assert c.as_dict() == {"accepted": 1, "rejected": {"length": 1, "magic": 1, "version": 1}, "rejected_total": 3}
    assert "version" in c.last_error


def test_sequence_tracker_gaps_duplicates_reorder():
    t = SequenceTracker()
    verdicts = [t.feed(s) for s in (10, 11, 14, 11, 12, 14, 15, 12)]
    assert verdicts == [SeqVerdict.NEW, SeqVerdict.NEW, SeqVerdict.NEW, SeqVerdict.DUPLICATE, SeqVerdict.STALE,
                        SeqVerdict.DUPLICATE, SeqVerdict.NEW, SeqVerdict.DUPLICATE]
    assert t.as_dict() == {"accepted": 4, "lost": 1, "reordered": 1, "duplicates": 3}  # 13 never came


def test_sequence_tracker_wraps_and_ignores_pre_start():
    t = SequenceTracker()
    for s in (2**32 - 2, 2**32 - 1, 0, 2):
        assert t.feed(s) is SeqVerdict.NEW
    assert t.feed(2**32 - 3) is SeqVerdict.STALE  # before the first message: not a filled gap
    assert (t.lost, t.reordered) == (1, 1)
    assert t.feed(2**31 + 5) is SeqVerdict.STALE  # more than half the space back
    t.reset()
    assert t.feed(0) is SeqVerdict.NEW and t.accepted == 1


def test_estimate_wire_bytes_formula():
    assert estimate_wire_bytes(88, ethernet=False) - 52 == 103  # measured zenoh 1.10.2 TCP stream bytes
    assert estimate_wire_bytes(88) == 88 + 13 + 2 + 52 + 38
    assert estimate_wire_bytes(88, "udp", ethernet=False) == 88 + 13 + 28
    assert estimate_wire_bytes(200) - estimate_wire_bytes(100) == 101  # 2-byte length VLE from 128
    assert estimate_wire_bytes(10, key_len=20) - estimate_wire_bytes(10) == 19
    with pytest.raises(ValueError):
        estimate_wire_bytes(1, "sctp")


def test_keys_layout_and_validation():
    k = Keys.make("lab/sea", "left_leg")
    assert k.state == "lab/sea/left_leg/state" and k.control == "lab/sea/left_leg/control"
    assert set(k.all()) == {"state", "setpoint", "voltage", "stats", "event", "control"}
    assert any_limb("sea", "stats") == "sea/*/stats"
    for prefix, limb in [("sea", "a/b"), ("sea", "l*"), ("sea", "$x"), ("sea", "a#"), ("sea", "a?"), ("sea", ""),
                         ("sea/", "l"), ("/sea", "l"), ("se*a", "l"), ("s ea", "l")]:
        with pytest.raises(ConfigError):
            Keys.make(prefix, limb)

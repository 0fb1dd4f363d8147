"""The hot encoders (`encode_state`, `encode_event_state`, `encode_setpoint`) give the bytes and the verdicts of the
payload constructors, and the one-call decode of STATE / EVENT_STATE / SETPOINT gives the general path's payloads."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from sea_hil.protocol.payload_fields import PayloadRejected
from sea_hil.protocol.payload_hot import encode_event_state, encode_setpoint, encode_state
from sea_hil.protocol.payloads import EventStatePayload, SetpointPayload, StatePayload, TriggerReason, decode, encode

GOOD = (0.1, -0.2)
PAIRS = [GOOD, [1, 2], (np.float64(0.5), np.float32(0.25)), np.array([0.3, 0.4]), (True, False), (1e308, 1e308),
         (math.nan, 0.0), (0.0, math.inf), (1.0,), (1.0, 2.0, 3.0), ("a", "b"), ("0.5", "1"), None, 3]
INTS = [0, 7, 2**32 - 1, 2**32, -1, True, 2.0, np.int64(3), 2**64]


def _outcome(fn, *args, **kw) -> tuple[str, object]:
    """("bytes", data) or (exception type, reason) of one call."""
    try:
        return "bytes", fn(*args, **kw)
    except PayloadRejected as err:
        return "rejected", err.reason
    except Exception as err:           # the constructor's own non-payload errors must match too
        return type(err).__name__, None


@pytest.mark.parametrize("slot", range(4))
@pytest.mark.parametrize("pair", PAIRS, ids=repr)
def test_encode_state_matches_the_constructor_for_every_pair(slot: int, pair: object) -> None:
    pairs = [GOOD] * 4
    pairs[slot] = pair
    hot = _outcome(encode_state, 1, 2, 3, *pairs, epoch=4)
    general = _outcome(lambda: encode(StatePayload(1, 2, 3, *pairs, epoch=4)))
    assert hot == general


@pytest.mark.parametrize("field", ["seq", "t_ns", "sample_t_ns", "epoch"])
@pytest.mark.parametrize("value", INTS, ids=repr)
def test_encode_state_matches_the_constructor_for_every_integer(field: str, value: object) -> None:
    ints = {"seq": 1, "t_ns": 2, "sample_t_ns": 3, "epoch": 4, field: value}
    args = (ints["seq"], ints["t_ns"], ints["sample_t_ns"], GOOD, GOOD, GOOD, GOOD)
    hot = _outcome(encode_state, *args, epoch=ints["epoch"])
    assert hot == _outcome(lambda: encode(StatePayload(*args, epoch=ints["epoch"])))


@pytest.mark.parametrize("reason", [*TriggerReason, 1, 9, "x"], ids=repr)
@pytest.mark.parametrize("pair", PAIRS, ids=repr)
def test_encode_setpoint_matches_the_constructor(pair: object, reason: object) -> None:
    for args in ((5, 6, 7, pair, GOOD, reason), (5, 6, 7, GOOD, pair, reason)):
        hot = _outcome(encode_setpoint, *args, epoch=8)
        assert hot == _outcome(lambda args=args: encode(SetpointPayload(*args, epoch=8)))
    for value in INTS:
        args = (5, value, 7, GOOD, GOOD, reason)
        assert _outcome(encode_setpoint, *args) == _outcome(lambda args=args: encode(SetpointPayload(*args)))


@pytest.mark.parametrize("slot", range(4))
@pytest.mark.parametrize("pair", PAIRS, ids=repr)
def test_encode_event_state_matches_the_constructor_for_every_pair(slot: int, pair: object) -> None:
    pairs = [GOOD] * 4
    pairs[slot] = pair
    args = (1, 2, 3, *pairs, 5, TriggerReason.ERROR_BOUND, 6)
    assert _outcome(encode_event_state, *args, epoch=4) == \
        _outcome(lambda: encode(EventStatePayload(*args, epoch=4)))


@pytest.mark.parametrize("field", ["seq", "t_ns", "sample_t_ns", "event_seq", "trajectory_id", "epoch"])
@pytest.mark.parametrize("value", INTS, ids=repr)
def test_encode_event_state_matches_the_constructor_for_every_integer(field: str, value: object) -> None:
    ints = {"seq": 1, "t_ns": 2, "sample_t_ns": 3, "event_seq": 5, "trajectory_id": 6, "epoch": 4, field: value}
    args = (ints["seq"], ints["t_ns"], ints["sample_t_ns"], GOOD, GOOD, GOOD, GOOD, ints["event_seq"],
            TriggerReason.TIME, ints["trajectory_id"])
    hot = _outcome(encode_event_state, *args, epoch=ints["epoch"])
    assert hot == _outcome(lambda: encode(EventStatePayload(*args, epoch=ints["epoch"])))


@pytest.mark.parametrize("reason", [*TriggerReason, 1, 9, "x", None], ids=repr)
def test_encode_event_state_matches_the_constructor_for_every_reason(reason: object) -> None:
    args = (1, 2, 3, GOOD, GOOD, GOOD, GOOD, 5, reason, 6)
    assert _outcome(encode_event_state, *args) == _outcome(lambda: encode(EventStatePayload(*args)))


def test_one_call_decode_of_an_event_state_keeps_the_general_verdicts() -> None:
    ev = EventStatePayload(4, 5, 6, (0.1, 0.2), (0.3, 0.4), (0.5, 0.6), (0.7, 0.8), 3, TriggerReason.INITIAL, 11,
                           epoch=2)
    raw = bytearray(encode(ev))
    assert type(decode(bytes(raw))) is EventStatePayload
    raw[-5] = 9                                    # an unknown reason byte: the enum verdict
    with pytest.raises(PayloadRejected) as err:
        decode(bytes(raw))
    assert err.value.reason.value == "enum"
    raw = bytearray(encode(ev))
    raw[32:40] = struct.pack("<d", math.nan)       # theta[0] not finite
    with pytest.raises(PayloadRejected) as err:
        decode(bytes(raw))
    assert err.value.reason.value == "nonfinite"


def test_one_call_decode_equals_the_general_payloads() -> None:
    state = StatePayload(4, 5, 6, (0.1, 0.2), (0.3, 0.4), (0.5, 0.6), (0.7, 0.8), epoch=9)
    sp = SetpointPayload(1, 2, 3, (0.01, 0.02), (-1.0, 1.0), TriggerReason.ERROR_BOUND, epoch=7)
    ev = EventStatePayload(4, 5, 6, (0.1, 0.2), (0.3, 0.4), (0.5, 0.6), (0.7, 0.8), 3, TriggerReason.TIME, 11)
    for p in (state, sp, ev):
        back = decode(encode(p))
        assert type(back) is type(p) and back == p and hash(back) == hash(p) and repr(back) == repr(p)
    assert decode(bytearray(encode(sp))) == sp and decode(memoryview(encode(state))) == state
    raw = bytearray(encode(sp))
    raw[-9:-1] = struct.pack("<d", math.inf)       # a non-finite float: the constructor's verdict
    with pytest.raises(PayloadRejected) as err:
        decode(bytes(raw))
    assert err.value.reason.value == "nonfinite"
    with pytest.raises(PayloadRejected) as err:    # the hot prefix but one byte short: the length verdict
        decode(encode(state)[:-1])
    assert err.value.reason.value == "length"


def test_pairs_of_one_and_three_are_refused_even_though_eight_floats_are_given() -> None:
    pairs = ((1.0,), (1.0, 2.0, 3.0), GOOD, GOOD)
    assert _outcome(encode_state, 1, 2, 3, *pairs) == ("rejected", _outcome(lambda: StatePayload(1, 2, 3, *pairs))[1])
    assert _outcome(encode_setpoint, 1, 2, 3, (1.0,), (1.0, 2.0, 3.0), TriggerReason.TIME)[0] == "rejected"

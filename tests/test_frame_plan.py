"""Precompiled frame plans (`sea_hil.protocol.frame_plan`) against cantools strict encoding/decoding of sea.dbc:
byte for byte over random in-range values and every signal's boundaries (and their tolerance edges), the same
decoded values for random payloads, and the same rejections out of range."""
from __future__ import annotations

import math
import random

import pytest
from cantools.database import EncodeError

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import load_database
from sea_hil.protocol.frame_plan import FramePlan

DB = load_database()
MESSAGES = [m for m in DB.messages if m.signals]
N_RANDOM = 200
REJECTED = (EncodeError, ValueError, OverflowError)   # what cantools strict raises (SeaCodec maps them all)


def _edges(sig) -> list[float]:
    tol = abs(sig.conversion.scale) * 1e-6
    lo, hi = sig.minimum, sig.maximum
    return [lo, hi, lo - tol, hi + tol, math.nextafter(lo, math.inf), math.nextafter(hi, -math.inf), 0.0,
            0 * sig.minimum - 0.0]


def _random_value(sig, rng: random.Random) -> float | int:
    if sig.conversion.scale == 1 and sig.conversion.offset == 0:
        return rng.randint(int(sig.minimum), int(sig.maximum))
    if rng.random() < 0.2:   # exactly on the raw grid and half-way between two raw steps (rounding ties)
        raw = rng.randint(round(sig.minimum / sig.conversion.scale), round(sig.maximum / sig.conversion.scale))
        return (raw + rng.choice((0.0, 0.5))) * sig.conversion.scale
    return rng.uniform(sig.minimum, sig.maximum)


def _rows(msg, rng: random.Random) -> list[dict[str, float]]:
    rows = [{s.name: _random_value(s, rng) for s in msg.signals} for _ in range(N_RANDOM)]
    for s in msg.signals:                 # each boundary of each signal, the others random
        for edge in _edges(s):
            if s.conversion.scale == 1 and s.conversion.offset == 0 and edge != int(edge):
                continue
            row = {t.name: _random_value(t, rng) for t in msg.signals}
            row[s.name] = int(edge) if s.conversion.scale == 1 else edge
            rows.append(row)
    return rows


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: m.name)
def test_encode_equals_cantools_strict(msg) -> None:
    plan, rng = FramePlan.of(msg), random.Random(17)
    for row in _rows(msg, rng):
        values = tuple(row[n] for n in plan.names)
        assert plan.encode(values) == msg.encode(row, strict=True), row


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: m.name)
def test_decode_equals_cantools(msg) -> None:
    plan, rng = FramePlan.of(msg), random.Random(18)
    payloads = [msg.encode({s.name: _random_value(s, rng) for s in msg.signals}, strict=True)
                for _ in range(N_RANDOM)]
    payloads += [rng.getrandbits(8 * msg.length).to_bytes(msg.length, "little") for _ in range(N_RANDOM)]
    for data in payloads:
        if int.from_bytes(data, "little") & ~plan.used_mask:
            with pytest.raises(MalformedFrame, match="reserved bits"):
                plan.decode(data)
            continue
        want = msg.decode(data, decode_choices=False, allow_excess=False)
        got = plan.decode(data)
        assert got == tuple(want[n] for n in plan.names)
        assert [type(v) for v in got] == [type(want[n]) for n in plan.names]


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: m.name)
def test_rejects_what_cantools_strict_rejects(msg) -> None:
    """Just outside each range (tolerance included), far outside, inf, NaN: a plan raises exactly when cantools
    strict does (a value-table signal accepts what rounds to a table entry, in cantools too), else the same bytes."""
    plan, rng = FramePlan.of(msg), random.Random(19)
    rejected = 0
    for s in msg.signals:
        tol = abs(s.conversion.scale) * 1e-6
        bad = [math.nextafter(s.minimum - tol, -math.inf), math.nextafter(s.maximum + tol, math.inf),
               s.minimum - 1.0, s.maximum + 1.0, math.inf, -math.inf, math.nan]
        for v in bad:
            row = {t.name: _random_value(t, rng) for t in msg.signals}
            row[s.name] = v
            values = tuple(row[n] for n in plan.names)
            try:
                want = msg.encode(row, strict=True)
            except REJECTED:   # out of range, or (inf, NaN) not convertible to a raw integer
                with pytest.raises(MalformedFrame, match=s.name):
                    plan.encode(values)
                rejected += 1
            else:
                assert s.choices and plan.encode(values) == want, (s.name, v)
        row = {t.name: _random_value(t, rng) for t in msg.signals}
        row[s.name] = "1.0"
        with pytest.raises(MalformedFrame, match="not a number"):
            plan.encode(tuple(row[n] for n in plan.names))
    assert rejected >= 5 * len(msg.signals)


def test_wrong_length_is_malformed() -> None:
    plan = FramePlan.of(DB.get_message_by_name("VOLTAGE_CMD"))
    with pytest.raises(MalformedFrame, match="expected 5"):
        plan.decode(b"\x00" * 4)


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: m.name)
def test_generated_fast_paths_equal_cantools(msg) -> None:
    """The generated `pack_plain` / `unpack_plain` (the hot paths): the cantools bytes and values where every value is
    plain and in range, None exactly where one is not (the codec's checking path takes over)."""
    plan, rng = FramePlan.of(msg), random.Random(20)
    packed = 0
    for row in _rows(msg, rng):
        values = tuple(row[n] for n in plan.names)
        inside = all(s.minimum <= row[s.name] <= s.maximum for s in msg.signals)
        got = plan.pack_plain(values)
        assert (got is not None) == inside, row
        if got is not None:
            assert got == msg.encode(row, strict=True)
            packed += 1
    assert packed >= N_RANDOM
    payloads = [(rng.getrandbits(8 * msg.length) & plan.used_mask).to_bytes(msg.length, "little")
                for _ in range(N_RANDOM)]
    payloads += [msg.encode({s.name: _random_value(s, rng) for s in msg.signals}, strict=True) for _ in range(50)]
    for data in payloads:
        want = msg.decode(data, decode_choices=False, allow_excess=False)
        fast = plan.unpack_plain(data)
        inside = all(s.minimum <= want[s.name] <= s.maximum and (not s.choices or want[s.name] in s.choices)
                     for s in msg.signals)
        assert (fast is not None) == inside
        assert plan.unpack(data) == tuple(want[n] for n in plan.names)
        if fast is not None:
            assert fast == plan.unpack(data)

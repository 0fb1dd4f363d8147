"""Sliding rates, stream statistics and bus load of the live view (sea_hil.stats.streams)."""
from __future__ import annotations

import pytest

from sea_hil.stats.streams import BusLoad, SlidingRate, StreamStats

S = 1_000_000_000


def test_sliding_rate_follows_a_rate_change() -> None:
    r = SlidingRate(window_s=1.0, slots=20)
    assert r.rates(0) == (0.0, 0.0)
    t = 0
    for _ in range(300):  # 100 msg/s of 10 bytes for 3 s
        r.add(t, 10)
        t += S // 100
    msgs, nbytes = r.rates(t)
    assert msgs == pytest.approx(100, rel=0.03) and nbytes == pytest.approx(1000, rel=0.03)
    for _ in range(2000):  # then 1000 msg/s for 2 s: the old rate has left the window
        r.add(t, 10)
        t += S // 1000
    assert r.rates(t)[0] == pytest.approx(1000, rel=0.03)
    assert r.rates(t + 5 * S) == (0.0, 0.0)


def test_stream_stats_totals_and_wire_estimate() -> None:
    s = StreamStats("sea/limb1/state", "tx", overhead_bytes=40)
    for i in range(10):
        s.add(i * S // 10, 77)
    s.add(S, 8, wire_bytes=17)
    d = s.to_dict(S)
    assert (d["messages"], d["payload_bytes"], d["wire_bytes"]) == (11, 778, 10 * 117 + 17)
    assert d["msgs_per_s"] == pytest.approx(10 / 0.95)


def test_bus_load_hand_computed_example() -> None:
    # 1000 std 8-byte frames/s + 1000 std 4-byte frames/s at 1 Mbit/s:
    # (135 + (32 + 47 + floor(65/4)=16 = 95)) * 1000 bit/s = 230 kbit/s = 23 %
    bus = BusLoad(1_000_000, window_s=0.5, start_ns=0)
    for i in range(2000):
        t = i * S // 1000
        bus.add_frame(t, 0x101, 8)
        bus.add_frame(t, 0x201, 4)
    end = 2 * S
    assert bus.session_load_pct(end) == pytest.approx(23.0)
    assert bus.window_load_pct(end) == pytest.approx(23.0, rel=0.02)
    d = bus.to_dict(end)
    assert d["per_id"] == [{"can_id": 0x101, "frames": 2000, "bits": 270_000},
                           {"can_id": 0x201, "frames": 2000, "bits": 190_000}]
    assert BusLoad(500_000).session_load_pct() == 0.0

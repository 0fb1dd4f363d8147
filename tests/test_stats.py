"""Statistics accumulators: histogram precision vs numpy, merge/serialise, rates, CAN bus load, tracking RMS."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sea_hil.errors import MalformedFrame, MalformedPayload
from sea_hil.stats.histogram import LogHistogram
from sea_hil.stats.session import (BusLoad, InterEventStats, SeqStats, SessionStats, SlidingRate, StreamStats,
                            TrackingStats, can_frame_bits)

S = 1_000_000_000
PCTS = (1, 10, 25, 50, 75, 90, 99, 99.9, 100)


def _filled(values: np.ndarray) -> LogHistogram:
    h = LogHistogram()
    for v in values:
        assert h.record(float(v))
    return h


def test_histogram_percentiles_match_numpy_within_precision() -> None:
    rng = np.random.default_rng(1)
    data = rng.lognormal(mean=math.log(0.01), sigma=2.0, size=20_000).clip(2e-6, 50.0)
    h = _filled(data)
    assert h.count == data.size
    assert h.min == data.min() and h.max == data.max()
    assert h.mean == pytest.approx(data.mean(), rel=1e-9)
    for p in PCTS:
        assert h.percentile(p) == pytest.approx(np.percentile(data, p, method="inverted_cdf"), rel=0.01), p


def test_histogram_is_fixed_size_and_handles_edges() -> None:
    h = LogHistogram()
    n_buckets = len(h._counts)
    for v in (0.0, 1e-9, 1e3, 5.0):
        h.record(v)
    assert not h.record(math.nan) and not h.record(-1.0) and not h.record(math.inf)
    assert h.rejected == 3 and h.count == 4 and len(h._counts) == n_buckets
    assert h.percentile(0) == 0.0 and h.percentile(100) == 1e3
    assert math.isnan(LogHistogram().percentile(50))
    assert LogHistogram().to_dict()["p50"] is None
    with pytest.raises(ValueError):
        h.percentile(101)


def test_histogram_merge_equals_histogram_of_union() -> None:
    rng = np.random.default_rng(2)
    a, b = rng.exponential(0.05, 3000), rng.exponential(2.0, 1000)
    ha, hb, hab = _filled(a), _filled(b), _filled(np.concatenate([a, b]))
    ha.merge(hb)
    assert ha.count == hab.count and ha._counts == hab._counts
    assert ha.to_dict() == pytest.approx(hab.to_dict())
    with pytest.raises(MalformedPayload):
        ha.merge(LogHistogram(precision=0.02))


def test_histogram_compact_form_roundtrips_through_json() -> None:
    h = _filled(np.random.default_rng(3).uniform(1e-5, 1.0, 500))
    back = LogHistogram.from_compact(json.loads(json.dumps(h.to_compact())))
    assert back.to_dict() == h.to_dict() and back._counts == h._counts
    assert LogHistogram.from_compact(LogHistogram().to_compact()).count == 0
    bad = h.to_compact()
    bad["n"] += 1
    with pytest.raises(MalformedPayload):
        LogHistogram.from_compact(bad)
    with pytest.raises(MalformedPayload):
        LogHistogram.from_compact({"v": 1})


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
    assert d["msgs_per_s"] == pytest.approx(10 / 0.95)  # window [0.05 s, 1 s] of 20 slots holds 10 messages


def test_can_frame_bits_formula() -> None:
    # hand-computed: std 8 bytes -> 64 data + 47 fixed (incl. 3 IFS) + floor(97/4)=24 stuff = 135
    assert can_frame_bits(8) == 135
    assert can_frame_bits(0) == 47 + 33 // 4 == 55
    assert can_frame_bits(8, extended=True) == 64 + 67 + 117 // 4 == 160
    assert can_frame_bits(15) == can_frame_bits(8)
    assert can_frame_bits(8, worst_case=False) == 111 and can_frame_bits(8, True, worst_case=False) == 131
    with pytest.raises(MalformedFrame):
        can_frame_bits(16)


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


def test_tracking_rms_and_max_match_numpy() -> None:
    rng = np.random.default_rng(4)
    desired = rng.normal(0, 1, (1000, 2))
    actual = desired + rng.normal(0, [0.01, 0.05], (1000, 2))
    t = TrackingStats(2)
    for d, a in zip(desired, actual):
        assert t.add(d, a)
    err = desired - actual
    assert t.rms == pytest.approx(np.sqrt(np.mean(err ** 2, axis=0)), rel=1e-9)
    assert t.max_abs == pytest.approx(np.abs(err).max(axis=0), rel=1e-12)
    assert not t.add([math.nan, 0.0], [0.0, 0.0]) and t.rejected == 1 and t.count == 1000


def test_inter_event_stats() -> None:
    ev = InterEventStats()
    assert ev.on_event(0, "threshold") is None
    times = [0.01, 0.05, 0.05, 0.25]
    t = 0
    for dt in times:
        t += int(dt * S)
        assert ev.on_event(t, "threshold" if dt < 0.2 else "max_interval") == pytest.approx(dt)
    d = ev.to_dict()
    assert d["events"] == 5 and d["by_reason"] == {"max_interval": 1, "threshold": 4}
    assert d["inter_event_s"]["min"] == pytest.approx(0.01) and d["inter_event_s"]["max"] == pytest.approx(0.25)
    assert d["inter_event_s"]["median"] == pytest.approx(0.05, rel=0.01)


def test_seq_stats_uses_tracker_or_external_counters() -> None:
    s = SeqStats()
    for q in (1, 2, 4, 3, 3, 6):
        s.observe(q)
    assert s.to_dict() == {"accepted": 4, "lost": 1, "reordered": 1, "duplicates": 1, "received": 6}
    s.set_counters(accepted=10, lost=2, reordered=0, duplicates=1)
    assert s.to_dict()["received"] == 11


def test_session_stats_json_and_flat_forms() -> None:
    st = SessionStats(can_bitrate_bps=1_000_000)
    st.stream("sea/limb1/state", "tx", 40).add(0, 80)
    st.histogram("state_latency").record(0.002)
    st.sequence("state").observe(7)
    st.bus.add_frame(0, 0x101, 8)
    st.tracking.add([0.1, 0.2], [0.1, 0.1])
    st.events.on_event(0, "threshold")
    st.count("malformed_frames")
    d = st.to_json_dict(S)
    assert list(d) == ["format", "t_ns", "streams", "latency_s", "seq", "can_bus", "tracking", "events", "counters"]
    json.dumps(d, allow_nan=False)
    flat = st.to_flat_dict(S)
    assert flat["stream_sea_limb1_state_tx_wire_bytes"] == 120
    assert flat["latency_state_latency_p50"] == pytest.approx(0.002, rel=0.01)
    assert flat["counter_malformed_frames"] == 1 and flat["events_reason_threshold"] == 1
    assert flat["tracking_max_abs_2"] == pytest.approx(0.1)
    assert all(isinstance(v, (int, float)) and k.replace("_", "").isalnum() for k, v in flat.items())

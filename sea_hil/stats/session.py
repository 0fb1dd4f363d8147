"""Pure statistics accumulators with O(1) memory per stream; every method takes explicit `t_ns` (no clocks here).

Not thread-safe: one owner per object (merge histograms across threads/processes via `LogHistogram.to_compact`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from sea_hil.errors import MalformedFrame
from sea_hil.stats.histogram import LogHistogram
from sea_hil.protocol.payloads import SequenceTracker

NS_PER_S = 1_000_000_000


class SlidingRate:
    """Messages/s and bytes/s over a sliding window of `window_s`, kept in `slots` time buckets (ring buffer)."""

    def __init__(self, window_s: float = 1.0, slots: int = 20) -> None:
        if window_s <= 0 or slots < 1:
            raise ValueError("window_s must be > 0 and slots >= 1")
        self.window_s = window_s
        self._slot_ns = max(1, int(window_s * NS_PER_S) // slots)
        self._ids = [-1] * slots
        self._msgs = [0] * slots
        self._bytes = [0] * slots
        self._first_ns: int | None = None

    def add(self, t_ns: int, nbytes: int = 0) -> None:
        """Count one message of `nbytes` at `t_ns` (events older than the window are ignored here)."""
        if self._first_ns is None or t_ns < self._first_ns:
            self._first_ns = t_ns
        idx = t_ns // self._slot_ns
        pos = idx % len(self._ids)
        if self._ids[pos] > idx:
            return
        if self._ids[pos] != idx:
            self._ids[pos], self._msgs[pos], self._bytes[pos] = idx, 0, 0
        self._msgs[pos] += 1
        self._bytes[pos] += nbytes

    def rates(self, now_ns: int) -> tuple[float, float]:
        """(messages/s, bytes/s) over ``[max(first event, now - window), now]``; (0, 0) before any data."""
        if self._first_ns is None:
            return 0.0, 0.0
        now_idx = now_ns // self._slot_ns
        oldest = now_idx - len(self._ids) + 1
        start_ns = max(oldest * self._slot_ns, self._first_ns)
        span_s = (now_ns - start_ns) / NS_PER_S
        if span_s <= 0:
            return 0.0, 0.0
        msgs = nbytes = 0
        for i, sid in enumerate(self._ids):
            if oldest <= sid <= now_idx:
                msgs += self._msgs[i]
                nbytes += self._bytes[i]
        return msgs / span_s, nbytes / span_s


class StreamStats:
    """Per (key or CAN id, direction): totals of messages, payload and estimated wire bytes, sliding bandwidth.

    Wire bytes default to ``payload + overhead_bytes`` (the caller's per-message framing estimate)."""

    def __init__(self, key: str, direction: str, overhead_bytes: int = 0, window_s: float = 1.0) -> None:
        self.key, self.direction, self.overhead_bytes = key, direction, overhead_bytes
        self.messages = 0
        self.payload_bytes = 0
        self.wire_bytes = 0
        self.rate = SlidingRate(window_s)

    def add(self, t_ns: int, payload_bytes: int, wire_bytes: int | None = None) -> None:
        wire = payload_bytes + self.overhead_bytes if wire_bytes is None else wire_bytes
        self.messages += 1
        self.payload_bytes += payload_bytes
        self.wire_bytes += wire
        self.rate.add(t_ns, wire)

    def to_dict(self, now_ns: int) -> dict[str, Any]:
        msgs_s, bytes_s = self.rate.rates(now_ns)
        return {"key": self.key, "direction": self.direction, "messages": self.messages,
                "payload_bytes": self.payload_bytes, "wire_bytes": self.wire_bytes,
                "msgs_per_s": msgs_s, "wire_bytes_per_s": bytes_s}


def can_frame_bits(dlc: int, extended: bool = False, *, worst_case: bool = True) -> int:
    """Bits on the wire of one classic CAN data frame including the 3-bit interframe space (Davis et al. 2007):
    standard ``8n + 47 + stuff``, extended ``8n + 67 + stuff`` with ``n = min(dlc, 8)``; worst-case bit stuffing
    ``stuff = floor((34 + 8n - 1)/4)`` (extended: ``54`` instead of ``34``), 0 when not `worst_case`.
    8-byte frames: 135 (std), 160 (ext) bits. The single copy of this formula (bus load, reports, docs)."""
    if not isinstance(dlc, int) or not 0 <= dlc <= 15:
        raise MalformedFrame(f"classic CAN dlc must be 0..15, got {dlc!r}")
    n = min(dlc, 8)
    fixed, stuffed = (67, 54) if extended else (47, 34)
    return 8 * n + fixed + ((stuffed + 8 * n - 1) // 4 if worst_case else 0)


class BusLoad:
    """CAN bus load from observed frames: per-id frame/bit counts, load % over the session and a sliding window.

    Session load = bits / (bitrate * (now - start)), where start is `start_ns` or the first frame's time."""

    def __init__(self, bitrate_bps: int, window_s: float = 1.0, start_ns: int | None = None) -> None:
        if bitrate_bps <= 0:
            raise ValueError("bitrate_bps must be > 0")
        self.bitrate_bps = bitrate_bps
        self.start_ns = start_ns
        self.total_bits = 0
        self.frames = 0
        self.per_id: dict[int, list[int]] = {}  # can_id -> [frames, bits]
        self._window = SlidingRate(window_s)
        self._last_ns: int | None = None

    def add_frame(self, t_ns: int, can_id: int, dlc: int, extended: bool = False) -> int:
        """Account one frame; returns its bit count."""
        bits = can_frame_bits(dlc, extended)
        if self.start_ns is None:
            self.start_ns = t_ns
        self._last_ns = t_ns if self._last_ns is None else max(self._last_ns, t_ns)
        entry = self.per_id.setdefault(can_id, [0, 0])
        entry[0] += 1
        entry[1] += bits
        self.frames += 1
        self.total_bits += bits
        self._window.add(t_ns, bits)
        return bits

    def session_load_pct(self, now_ns: int | None = None) -> float:
        end = now_ns if now_ns is not None else self._last_ns
        if self.start_ns is None or end is None or end <= self.start_ns:
            return 0.0
        return 100.0 * self.total_bits * NS_PER_S / (self.bitrate_bps * (end - self.start_ns))

    def window_load_pct(self, now_ns: int) -> float:
        return 100.0 * self._window.rates(now_ns)[1] / self.bitrate_bps

    def to_dict(self, now_ns: int) -> dict[str, Any]:
        return {"bitrate_bps": self.bitrate_bps, "frames": self.frames, "bits": self.total_bits,
                "load_pct_session": self.session_load_pct(now_ns), "load_pct_window": self.window_load_pct(now_ns),
                "per_id": [{"can_id": k, "frames": f, "bits": b} for k, (f, b) in sorted(self.per_id.items())]}


class SeqStats:
    """Loss/reorder/duplicate counters of one u32 sequence stream. Tracking is `payloads.SequenceTracker`'s job:
    `observe(seq)` feeds an owned tracker; a component with its own tracker passes its counters to `set_counters`."""

    def __init__(self, window: int = 64) -> None:
        self.tracker = SequenceTracker(window)
        self._external: dict[str, int] | None = None

    def observe(self, seq: int) -> None:
        self.tracker.feed(seq)

    def set_counters(self, *, accepted: int, lost: int, reordered: int, duplicates: int) -> None:
        self._external = {"accepted": accepted, "lost": lost, "reordered": reordered, "duplicates": duplicates}

    def to_dict(self) -> dict[str, int]:
        d = dict(self._external) if self._external is not None else self.tracker.as_dict()
        d["received"] = d["accepted"] + d["reordered"] + d["duplicates"]
        return d


class TrackingStats:
    """Per-joint max |error| and RMS error (running sums) from (desired, actual) samples; non-finite rejected."""

    def __init__(self, joints: int = 2) -> None:
        self.count = 0
        self.rejected = 0
        self._sum_sq = [0.0] * joints
        self.max_abs = [0.0] * joints

    def add(self, desired: Sequence[float], actual: Sequence[float]) -> bool:
        if len(desired) != len(self._sum_sq) or len(actual) != len(self._sum_sq):
            raise ValueError(f"expected {len(self._sum_sq)} joints")
        errs = [d - a for d, a in zip(desired, actual)]
        if not all(math.isfinite(e) for e in errs):
            self.rejected += 1
            return False
        self.count += 1
        for j, e in enumerate(errs):
            self._sum_sq[j] += e * e
            self.max_abs[j] = max(self.max_abs[j], abs(e))
        return True

    @property
    def rms(self) -> list[float]:
        return [math.sqrt(s / self.count) if self.count else math.nan for s in self._sum_sq]

    def to_dict(self) -> dict[str, Any]:
        rms = self.rms if self.count else [None] * len(self._sum_sq)
        return {"samples": self.count, "rejected": self.rejected, "rms": rms, "max_abs": list(self.max_abs)}


class InterEventStats:
    """Trigger events: inter-event times in seconds (histogram) and counts by reason."""

    def __init__(self) -> None:
        self.hist = LogHistogram()
        self.by_reason: dict[str, int] = {}
        self.events = 0
        self._last_ns: int | None = None

    def on_event(self, t_ns: int, reason: str) -> float | None:
        """Count an event; returns the inter-event time in seconds (None for the first event)."""
        self.events += 1
        self.by_reason[reason] = self.by_reason.get(reason, 0) + 1
        last, self._last_ns = self._last_ns, t_ns
        if last is None:
            return None
        dt_s = (t_ns - last) / NS_PER_S
        self.hist.record(dt_s)
        return dt_s

    def to_dict(self) -> dict[str, Any]:
        h = self.hist.to_dict()
        return {"events": self.events, "by_reason": dict(sorted(self.by_reason.items())),
                "inter_event_s": {"min": h["min"], "median": h["p50"], "max": h["max"], **h}}


def _flat_key(*parts: object) -> str:
    return "_".join("".join(ch if ch.isalnum() else "_" for ch in str(p)).strip("_") for p in parts)


class SessionStats:
    """Container of named accumulators with a stable JSON form (layout `STATS_FORMAT`, see docs/recording.md)."""

    STATS_FORMAT = "sea-hil.stats/1"

    def __init__(self, can_bitrate_bps: int | None = None, joints: int = 2) -> None:
        self.streams: dict[tuple[str, str], StreamStats] = {}
        self.latency: dict[str, LogHistogram] = {}
        self.seq: dict[str, SeqStats] = {}
        self.counters: dict[str, int] = {}
        self.bus = BusLoad(can_bitrate_bps) if can_bitrate_bps else None
        self.tracking = TrackingStats(joints)
        self.events = InterEventStats()

    def stream(self, key: str, direction: str, overhead_bytes: int = 0) -> StreamStats:
        s = self.streams.get((key, direction))
        if s is None:
            s = self.streams[(key, direction)] = StreamStats(key, direction, overhead_bytes)
        return s

    def histogram(self, name: str) -> LogHistogram:
        return self.latency.setdefault(name, LogHistogram())

    def sequence(self, name: str) -> SeqStats:
        return self.seq.setdefault(name, SeqStats())

    def count(self, name: str, n: int = 1) -> None:
        self.counters[name] = self.counters.get(name, 0) + n

    def to_json_dict(self, now_ns: int) -> dict[str, Any]:
        return {"format": self.STATS_FORMAT, "t_ns": now_ns,
                "streams": [s.to_dict(now_ns) for _, s in sorted(self.streams.items())],
                "latency_s": {k: h.to_dict() for k, h in sorted(self.latency.items())},
                "seq": {k: s.to_dict() for k, s in sorted(self.seq.items())},
                "can_bus": self.bus.to_dict(now_ns) if self.bus else None,
                "tracking": self.tracking.to_dict(), "events": self.events.to_dict(),
                "counters": dict(sorted(self.counters.items()))}

    def to_flat_dict(self, now_ns: int) -> dict[str, float | int]:
        """Flat numeric fields for the `/stats` MCAP channel (None values omitted, keys `[A-Za-z0-9_]`)."""
        d = self.to_json_dict(now_ns)
        out: dict[str, float | int] = {"t_ns": now_ns}
        for s in d["streams"]:
            for f in ("messages", "payload_bytes", "wire_bytes", "msgs_per_s", "wire_bytes_per_s"):
                out[_flat_key("stream", s["key"], s["direction"], f)] = s[f]
        for name, h in d["latency_s"].items():
            out.update({_flat_key("latency", name, f): v for f, v in h.items()})
        for name, q in d["seq"].items():
            out.update({_flat_key("seq", name, f): v for f, v in q.items()})
        if d["can_bus"]:
            out.update({_flat_key("can", f): d["can_bus"][f] for f in ("frames", "load_pct_session", "load_pct_window")})
        t = d["tracking"]
        for j in range(len(t["rms"])):
            out[_flat_key("tracking_rms", j + 1)] = t["rms"][j]
            out[_flat_key("tracking_max_abs", j + 1)] = t["max_abs"][j]
        out["events"] = d["events"]["events"]
        out.update({_flat_key("events_inter_event_s", f): v for f, v in d["events"]["inter_event_s"].items()})
        out.update({_flat_key("events_reason", k): v for k, v in d["events"]["by_reason"].items()})
        out.update({_flat_key("counter", k): v for k, v in d["counters"].items()})
        return {k: v for k, v in out.items() if v is not None}

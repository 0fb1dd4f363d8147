"""Streaming accumulators for live statistics: message and byte rates over a sliding window (`SlidingRate`,
`StreamStats`) and CAN bus load from the frames seen (`BusLoad`, worst-case stuffing via `can_frame_bits`). Used by
the live view (`sea_hil.live.view`)."""
from __future__ import annotations

import math
from typing import Any

from sea_hil.stats.can_bits import can_frame_bits, nominal_bits

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


class BusLoad:
    """CAN bus load from observed frames: per-id frame/bit counts, load % over the session and a sliding window.

    Session load = bits / (bitrate * (now - start)), where start is `start_ns` or the first frame's time."""

    def __init__(self, bitrate_bps: int, window_s: float = 1.0, start_ns: int | None = None,
                 data_bitrate_bps: int = 5_000_000) -> None:
        if bitrate_bps <= 0 or data_bitrate_bps <= 0:
            raise ValueError("bitrate_bps and data_bitrate_bps must be > 0")
        self.bitrate_bps, self.data_bitrate_bps = bitrate_bps, data_bitrate_bps
        self.start_ns = start_ns
        self.total_bits = 0
        self.frames = 0
        self.per_id: dict[int, list[int]] = {}  # can_id -> [frames, bits]
        self._window = SlidingRate(window_s)
        self._last_ns: int | None = None

    def add_frame(self, t_ns: int, can_id: int, dlc: int, extended: bool = False, fd: bool = False) -> int:
        """Account one frame; returns its bit count (a CAN FD frame's bus time in nominal bits, rounded up)."""
        bits = can_frame_bits(dlc, extended) if not fd else math.ceil(nominal_bits(
            dlc, extended=extended, fd=True, bitrate_bps=self.bitrate_bps, data_bitrate_bps=self.data_bitrate_bps))
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

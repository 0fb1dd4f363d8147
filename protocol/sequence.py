"""Newest-wins sequence tracking of one u32 message stream (lost, reordered, duplicated messages)."""
from __future__ import annotations

from enum import IntEnum

from sea_hil.protocol.payload_fields import U32_MAX, uint_field


class SeqVerdict(IntEnum):
    NEW = 0        # newer than every accepted message: use it
    DUPLICATE = 1  # already seen
    STALE = 2      # older than the newest accepted (arrived late / reordered): ignore it


class SequenceTracker:
    """Newest-wins tracking of one u32 stream (RFC 1982 serial arithmetic, so seq may wrap).

    `lost` counts skipped sequence numbers; a skipped number that still arrives within the last `window` numbers
    is moved from `lost` to `reordered`. Older arrivals cannot be classified and count as `reordered`. Call
    `restart()` when the sender restarts its sequence (`reset()` also clears the counters).
    """

    def __init__(self, window: int = 64) -> None:
        if window < 1:
            raise ValueError("window must be >= 1")
        self.window = window
        self.reset()

    def reset(self) -> None:
        self.last: int | None = None
        self._seen = 0  # bit i set = (last - i) was seen
        self._span = 0  # how many numbers back from `last` the bitmap covers (<= window; stops at the first)
        self.accepted = self.lost = self.reordered = self.duplicates = 0

    def restart(self) -> None:
        """The sender restarted its sequence: forget the window, keep the counters (the next seq is NEW)."""
        self.last, self._seen, self._span = None, 0, 0

    def feed(self, seq: int) -> SeqVerdict:
        seq = uint_field("seq", seq, U32_MAX)
        mask = (1 << self.window) - 1
        if self.last is None:
            self.last, self._seen, self._span, self.accepted = seq, 1, 1, self.accepted + 1
            return SeqVerdict.NEW
        ahead = (seq - self.last) & U32_MAX
        if ahead == 0:
            self.duplicates += 1
            return SeqVerdict.DUPLICATE
        if ahead < 1 << 31:
            self.lost += ahead - 1
            self._seen = ((self._seen << ahead) | 1) & mask if ahead < self.window else 1
            self._span = min(self._span + ahead, self.window)
            self.last = seq
            self.accepted += 1
            return SeqVerdict.NEW
        back = (self.last - seq) & U32_MAX
        if back < self._span:
            if self._seen >> back & 1:
                self.duplicates += 1
                return SeqVerdict.DUPLICATE
            self._seen |= 1 << back
            self.lost -= 1
        self.reordered += 1
        return SeqVerdict.STALE

    def as_dict(self) -> dict[str, int]:
        return {"accepted": self.accepted, "lost": self.lost, "reordered": self.reordered,
                "duplicates": self.duplicates}

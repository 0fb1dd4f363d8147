"""Rolling 16-bit time / 8-bit sequence arithmetic and the pairing of the three feedback frames of one sample."""
from __future__ import annotations

import numbers
from collections import OrderedDict, deque
from typing import Any

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_frames import (
    FEEDBACK_PARTS,
    SEQ_MODULUS,
    T_US_MODULUS,
    Feedback,
    FeedbackAngle,
    FeedbackJoint1,
    FeedbackJoint2,
)


def unwrap_us(prev_full_us: int, wrapped: int) -> int:
    """The full time whose low 16 bits are `wrapped` nearest to `prev_full_us` (valid for |gap| < 32.768 ms)."""
    if not (type(wrapped) is int or isinstance(wrapped, numbers.Integral)) or not 0 <= wrapped < T_US_MODULUS:
        # (a plain int first: the ABC check costs ~1 us, and the edge unwraps every sample)
        raise MalformedFrame(f"t_us {wrapped!r} not in 0..{T_US_MODULUS - 1}")
    half = T_US_MODULUS // 2
    return prev_full_us + (wrapped - prev_full_us + half) % T_US_MODULUS - half


def seq_gap(prev_seq: int, seq: int) -> int:
    """Forward distance prev_seq -> seq of the rolling 8-bit counters (1 = consecutive, 0 = repeat)."""
    return (seq - prev_seq) % SEQ_MODULUS


class FeedbackAssembler:
    """Pairs the three feedback frames of one (node, seq) into a `Feedback`.

    A sample is dropped (`incomplete` += 1) when a later sample completes first or more than `max_pending`
    samples are open; a frame of an already closed sample or a duplicate part is dropped (`stale` += 1).
    """

    def __init__(self, max_pending: int = 4) -> None:
        self._max_pending = max(1, max_pending)
        self._pending: dict[int, OrderedDict[int, dict[type, Any]]] = {}
        self._closed: dict[int, deque[int]] = {}
        self.incomplete = 0
        self.stale = 0

    def push(self, part: FeedbackAngle | FeedbackJoint1 | FeedbackJoint2) -> Feedback | None:
        if not isinstance(part, FEEDBACK_PARTS):
            raise TypeError(f"FeedbackAssembler.push needs a feedback frame, got {type(part).__name__}")
        node, seq = part.node_id, part.seq
        pending = self._pending.get(node)
        if pending is None:   # first frame of this node (no throw-away containers per frame)
            pending = self._pending[node] = OrderedDict()
            self._closed[node] = deque(maxlen=2 * self._max_pending)
        closed = self._closed[node]
        parts = pending.get(seq, {})
        if seq in closed or type(part) in parts:
            self.stale += 1
            return None
        parts[type(part)] = part
        pending[seq] = parts
        if len(parts) == len(FEEDBACK_PARTS):
            while True:
                old, _ = pending.popitem(last=False)
                closed.append(old)
                if old == seq:
                    break
                self.incomplete += 1
            return Feedback.from_parts(parts[FeedbackAngle], parts[FeedbackJoint1], parts[FeedbackJoint2])
        while len(pending) > self._max_pending:
            closed.append(pending.popitem(last=False)[0])
            self.incomplete += 1
        return None

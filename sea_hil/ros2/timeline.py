"""Who and when in a recording, for the bag export: which limb a CAN node or a Zenoh key belongs to (`Limbs`), and
the session's sample time of a drive node at a log time (`NodeClock`) or of a limb's state number (`StateClock`)
(docs/ros2.md, "Clocks"). Pure bookkeeping over a `SessionData`'s messages."""
from __future__ import annotations

import bisect
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_assembly import unwrap_us
from sea_hil.recorder.reader import RecordedMessage, SessionData


@dataclass(frozen=True)
class Limbs:
    """Which limbs the recording holds and which CAN node id is whose (metadata `sea-hil.limbs`: name -> "node_id
    bus"; without it, the limb names of the Zenoh keys, and every node to the one limb if there is one)."""
    names: tuple[str, ...]
    node_limb: Mapping[int, str]

    @classmethod
    def of(cls, data: SessionData) -> Limbs:
        meta = data.metadata.get("sea-hil.limbs", {})
        node_limb: dict[int, str] = {}
        for name, spec in meta.items():
            try:
                node_limb[int(str(spec).split()[0])] = name
            except (ValueError, IndexError):
                continue
        names = set(node_limb.values())
        for topic in ("/zenoh/state", "/zenoh/setpoint", "/tracking"):
            names.update(filter(None, (limb_of_key(m.payload.get("key")) for m in data.messages.get(topic, []))))
        ordered = tuple(sorted(names))
        if not node_limb and len(ordered) == 1:
            nodes = {m.payload.get("node_id") for m in data.messages.get("/can/raw", [])}
            node_limb = {n: ordered[0] for n in nodes if isinstance(n, int)}
        return cls(ordered, node_limb)

    def ns(self, limb: str | None) -> str:
        """The topic namespace of `limb`: "" for a one-limb session (or an unknown limb), else `/<limb>`."""
        return f"/{limb}" if limb and len(self.names) > 1 else ""

    def of_node(self, node_id: Any) -> str | None:
        return self.node_limb.get(node_id) if isinstance(node_id, int) else None


def limb_of_key(key: Any) -> str | None:
    """`sea/limb1/state` -> `limb1`."""
    if not isinstance(key, str) or key.count("/") < 1:
        return None
    return key.rsplit("/", 2)[-2] or None


class NodeClock:
    """The drive's sample time at a log time: per node, the log times of its FEEDBACK_ANGLE (or CAN FD FEEDBACK)
    messages and their `t_us`, unwrapped. A node before its first feedback (or none) falls back to the newest sample
    time of any node at that log time (0 before any)."""

    def __init__(self, feedback: Iterable[RecordedMessage]) -> None:
        self._log: dict[int, list[int]] = {}
        self._sample: dict[int, list[int]] = {}
        full: dict[int, int] = {}
        all_log: list[int] = []
        all_max: list[int] = []
        newest = 0
        for m in feedback:
            p = m.payload
            node, t_us = p.get("node_id"), p.get("t_us")
            if not isinstance(node, int) or not isinstance(t_us, int):
                continue
            try:
                us = t_us if node not in full else unwrap_us(full[node], t_us)
            except MalformedFrame:
                continue
            full[node] = us
            self._log.setdefault(node, []).append(m.log_time_ns)
            self._sample.setdefault(node, []).append(us * 1000)
            newest = max(newest, us * 1000)
            all_log.append(m.log_time_ns)
            all_max.append(newest)
        self._all_log, self._all_max = all_log, all_max

    def at(self, node_id: Any, log_time_ns: int) -> int:
        logs = self._log.get(node_id) if isinstance(node_id, int) else None
        if logs:
            i = bisect.bisect_right(logs, log_time_ns)
            if i:
                return self._sample[node_id][i - 1]
        return self.newest(log_time_ns)

    def newest(self, log_time_ns: int) -> int:
        j = bisect.bisect_right(self._all_log, log_time_ns)
        return self._all_max[j - 1] if j else 0


class StateClock:
    """Sample time of a state number of one limb: exact for the states recorded (`/zenoh/state`), else counted
    from the nearest recorded state at the sample period (the edge's state numbers step by one per sample)."""

    def __init__(self, states: Iterable[RecordedMessage], default_period_ns: int) -> None:
        known: dict[int, int] = {}
        for m in states:
            seq, t = m.payload.get("seq"), m.payload.get("sample_t_ns")
            if isinstance(seq, int) and isinstance(t, int):
                known.setdefault(seq, t)
        self._known = known
        self._seqs = sorted(known)
        period = default_period_ns
        if len(self._seqs) >= 2 and self._seqs[-1] > self._seqs[0]:
            span = known[self._seqs[-1]] - known[self._seqs[0]]
            period = max(1, round(span / (self._seqs[-1] - self._seqs[0])))
        self.period_ns = period

    def at(self, seq: Any) -> int | None:
        if not isinstance(seq, int):
            return None
        if seq in self._known:
            return self._known[seq]
        if not self._seqs:
            return max(0, (seq - 1) * self.period_ns)
        i = bisect.bisect_right(self._seqs, seq)
        base = self._seqs[i - 1] if i else self._seqs[0]
        return max(0, self._known[base] + (seq - base) * self.period_ns)



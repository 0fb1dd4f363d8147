"""The edge's state publisher: one `StatePayload` per outer sample (the paper's placement) or one `EventStatePayload`
per event of the edge's trigger (`publish_event`), through the uplink link emulator, with the wall time and sample
time of each published state kept (for the closed-loop and simulated latencies). The header `t_ns` is the clock's
stamp (`stamp(delivery_ns)`): the sender's monotonic clock in real time, the emulated link's delivery time on the
simulated clock in lockstep (so the controller measures the uplink delay of every state: `sea_hil.runtime`)."""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from sea_hil.protocol.can_frames import Feedback
from sea_hil.protocol.payload_hot import encode_state
from sea_hil.protocol.payloads import PAYLOAD_SIZE, EventStatePayload, MsgType, encode
from sea_hil.protocol.wire_size import estimate_wire_bytes
from sea_hil.protocol.zsession import LinkedPublisher

KEEP = 1000   # states remembered for latency bookkeeping


class StatePublisher:
    def __init__(self, uplink: LinkedPublisher, counters: Any, epoch: int = 0,
                 stamp: Callable[[int], int] = lambda at_ns: time.monotonic_ns()) -> None:
        self.uplink = uplink
        self.epoch = epoch                      # this edge's session epoch (sea_hil.protocol.epoch)
        self.counters = counters
        self.stamp = stamp
        self.seq = 0
        self.sent_at: dict[int, int] = {}       # state seq -> wall time published
        self.sampled_at: dict[int, int] = {}    # state seq -> sample time

    def publish(self, fb: Feedback, sample_t_ns: int) -> tuple[int, bytes, int | None]:
        """Publish the state of `fb` (sampled at `sample_t_ns`); (seq, payload, delivery time or None if lost)."""
        self.seq += 1
        return self._put(self.seq, sample_t_ns, PAYLOAD_SIZE[MsgType.STATE],
                         lambda t: encode_state(self.seq, t, sample_t_ns, fb.theta_rad, fb.omega_rad_s, fb.delta_m,
                                                fb.nut_vel_m_s, epoch=self.epoch))

    def publish_event(self, fb: Feedback, sample_t_ns: int, seq: int, event_seq: int, reason: Any,
                      trajectory_id: int) -> tuple[int, bytes, int | None]:
        """Publish the event state `seq` (the sample index + 1) the edge's trigger chose."""
        self.seq = seq
        return self._put(seq, sample_t_ns, PAYLOAD_SIZE[MsgType.EVENT_STATE],
                         lambda t: encode(EventStatePayload(seq, t, sample_t_ns, fb.theta_rad, fb.omega_rad_s,
                                                            fb.delta_m, fb.nut_vel_m_s, event_seq, reason,
                                                            trajectory_id, epoch=self.epoch)))

    def _put(self, seq: int, sample_t_ns: int, size: int, make: Callable[[int], bytes]
             ) -> tuple[int, bytes, int | None]:
        for book, value in ((self.sent_at, time.monotonic_ns()), (self.sampled_at, sample_t_ns)):
            book[seq] = value
            if len(book) > KEEP:
                del book[next(iter(book))]
        made: list[bytes] = []

        def data(at_ns: int) -> bytes:
            made.append(make(self.stamp(at_ns)))
            return made[0]
        at = self.uplink.put(data, sample_t_ns, wire_bytes=estimate_wire_bytes(size))
        if at is not None:      # None: lost on the emulated link, never awaited
            self.counters.states_sent += 1
            self.counters.state_bytes += size
        return seq, made[0] if made else b"", at

    def poll(self, now_ns: int) -> None:
        self.uplink.poll(now_ns)

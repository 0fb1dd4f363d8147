"""The edge's state publisher: one `StatePayload` per outer sample through the uplink link emulator, with the
wall time and sample time of each published state kept (for the closed-loop and simulated latencies)."""
from __future__ import annotations

import time
from typing import Any

from sea_hil.protocol.can_frames import Feedback
from sea_hil.protocol.payloads import StatePayload, encode
from sea_hil.protocol.zsession import LinkedPublisher

KEEP = 1000   # states remembered for latency bookkeeping


class StatePublisher:
    def __init__(self, uplink: LinkedPublisher, counters: Any, epoch: int = 0) -> None:
        self.uplink = uplink
        self.epoch = epoch                      # this edge's session epoch (sea_hil.protocol.epoch)
        self.counters = counters
        self.seq = 0
        self.sent_at: dict[int, int] = {}       # state seq -> wall time published
        self.sampled_at: dict[int, int] = {}    # state seq -> sample time

    def publish(self, fb: Feedback, sample_t_ns: int) -> tuple[int, bytes, int | None]:
        """Publish the state of `fb` (sampled at `sample_t_ns`); (seq, payload, delivery time or None if lost)."""
        self.seq += 1
        t = time.monotonic_ns()
        data = encode(StatePayload(self.seq, t, sample_t_ns, fb.theta_rad, fb.omega_rad_s, fb.delta_m,
                                   fb.nut_vel_m_s, epoch=self.epoch))
        self.sent_at[self.seq] = t
        self.sent_at.pop(self.seq - KEEP, None)
        self.sampled_at[self.seq] = sample_t_ns
        self.sampled_at.pop(self.seq - KEEP, None)
        at = self.uplink.put(data, sample_t_ns)
        if at is not None:      # None: lost on the emulated link, never awaited
            self.counters.states_sent += 1
            self.counters.state_bytes += len(data)
        return self.seq, data, at

    def poll(self, now_ns: int) -> None:
        self.uplink.poll(now_ns)

"""The edge's setpoint intake: setpoint/voltage payloads from Zenoh are checked (malformed, wrong type, an old or
foreign session epoch, stale or duplicated seqs are counted and dropped; a controller restart -- a new epoch -- is
accepted when the clock allows it), pass the downlink link emulator, and are applied when it releases them (`take`),
unless the state they answer was sampled more than `max_answer_age_ns` before (`late_setpoints`: a controller path
starved or congested for longer would steer the limb on an old state; the setpoint timeout then makes the drive
safe if no fresh answer comes)."""
from __future__ import annotations

import logging
import time
from typing import Any

from sea_hil.protocol.epoch import EpochVerdict, PeerEpoch
from sea_hil.protocol.keys import KEY_PAYLOADS
from sea_hil.protocol.link import DelayQueue, LinkEmulator
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType, PayloadCounters, SetpointPayload, VoltagePayload
from sea_hil.protocol.sequence import SequenceTracker, SeqVerdict
from sea_hil.runtime.clock import EdgeSync

log = logging.getLogger("sea_hil.edge")
SETPOINT_BYTES = PAYLOAD_SIZE[MsgType.SETPOINT]


class SetpointIntake:
    def __init__(self, downlink: LinkEmulator, counters: Any, payloads: PayloadCounters, timeout_ns: int,
                 sync: EdgeSync, envelope: Any = None, max_answer_age_ns: int = 0, inner: str = "edge") -> None:
        self.downlink = downlink
        self.inner = inner                        # "edge": setpoints only; "remote": tunnelled voltages only
        self.channel = "setpoint" if inner == "edge" else "voltage"
        self.counters = counters
        self.payloads = payloads
        self.timeout_ns = timeout_ns
        self.sync = sync
        self.envelope = envelope                  # `EnvelopeGate` (controller/envelope.py) or None: admit all
        self.max_answer_age_ns = max_answer_age_ns  # 0: off
        self.sp_seq = SequenceTracker()
        self.epoch = PeerEpoch("controller", log)
        self.pending: DelayQueue[object] = DelayQueue()
        self.seen_setpoints: set[int] = set()
        self.last_rx_ns = 0                       # sample time of the newest accepted setpoint/voltage
        self.last_setpoint_ns: int | None = None  # sample time of the newest applied one

    def submit(self, data: bytes, sample_t_ns: int, sent_at: dict[int, int], rx_ns: int | None,
               channel: str | None = None) -> bool:
        """One payload from key `channel` ("setpoint" | "voltage"; None: the one of the inner loop's placement) at
        sample time `sample_t_ns`; True if it entered the downlink emulator. Closed-loop latency (`latency`) =
        arrival - publication of the state it answers, plus the delay the downlink emulator adds. A payload of
        another type than its key carries (`payload_rejected_key`), or on the key of the other inner placement (a
        voltage with the inner loop at the edge: `unexpected_payloads`), is rejected before the sequence check."""
        channel = channel or self.channel
        p = self.payloads.try_decode(data, KEY_PAYLOADS[channel])
        if p is None:
            return False
        assert isinstance(p, (SetpointPayload, VoltagePayload))   # the only types of the two downlink keys
        if channel != self.channel:
            self.counters.unexpected_payloads += 1
            if self.counters.unexpected_payloads in (1, 10) or self.counters.unexpected_payloads % 1000 == 0:
                log.warning("%s payload dropped (%d so far): the inner loop runs %s, its key is %r", channel,
                            self.counters.unexpected_payloads, self.inner, self.channel)
            return False
        verdict = self.epoch.check(p.epoch, lambda: self._restart_allowed(p.seq, sample_t_ns))
        if verdict is EpochVerdict.REJECTED:
            return False
        if verdict is EpochVerdict.RESTART:
            self._controller_restarted(p.seq)
        elif self.sp_seq.feed(p.seq) is not SeqVerdict.NEW:
            self.counters.stale_setpoints += 1
            return False
        self.seen_setpoints.add(p.seq)
        self.last_rx_ns = sample_t_ns
        if isinstance(p, SetpointPayload) and self.envelope is not None \
                and not self.envelope.admit(p.seq, p.deflection_m):
            return False        # out of the envelope: seen (lockstep goes on), counted, never applied
        at = self.downlink.submit(sample_t_ns, len(data))
        if at is not None:
            self.pending.push(at, p)
            sent = sent_at.get(p.state_seq)
            if sent is not None and rx_ns is not None:
                self.counters.latency.record((max(rx_ns - sent, 0) + max(at - sample_t_ns, 0)) * 1e-9)
        return True

    def _restart_allowed(self, seq: int, sample_t_ns: int) -> bool:
        """A new controller epoch starts a new setpoint stream only after the old one timed out (the driver is then
        in its safe state) and only if it looks like a fresh sender (seq < the tracker window)."""
        timed_out = sample_t_ns - self.last_rx_ns > self.timeout_ns
        return self.sync.restart_possible(timed_out) and seq < self.sp_seq.window

    def _controller_restarted(self, seq: int) -> None:
        self.sp_seq.restart()
        self.sp_seq.feed(seq)
        self.seen_setpoints.clear()
        self.counters.controller_restarts += 1
        log.warning("setpoint stream restarted at seq %d (controller restart)", seq)

    def fresh(self, now_ns: int) -> bool:
        return self.last_setpoint_ns is not None and now_ns - self.last_setpoint_ns <= self.timeout_ns

    def take(self, now_ns: int, sent_at: dict[int, int], sampled_at: dict[int, int], apply: Any) -> bool:
        """Apply (`apply(payload)`) what the downlink emulator releases by sample time `now_ns`; True if any."""
        applied = False
        for p in self.pending.pop_due(now_ns):
            sampled = sampled_at.get(p.state_seq)   # type: ignore[attr-defined]
            if self._late(p, now_ns, sampled):
                continue
            applied = True
            t = time.monotonic_ns()
            sent = sent_at.get(p.state_seq)   # type: ignore[attr-defined]
            if sent is not None:
                self.counters.apply_latency.record(max(t - sent, 1000) * 1e-9)
            if sampled is not None:
                self.counters.sim_latency.record((now_ns - sampled) * 1e-9)
            self.last_setpoint_ns = now_ns
            apply(p)
        return applied

    def _late(self, p: Any, now_ns: int, sampled_ns: int | None) -> bool:
        """The answer to a state sampled more than `max_answer_age_ns` before `now_ns`: counted, logged, dropped."""
        if not self.max_answer_age_ns or sampled_ns is None or now_ns - sampled_ns <= self.max_answer_age_ns:
            return False
        self.counters.late_setpoints += 1
        n = self.counters.late_setpoints
        if n <= 10 or n % 100 == 0:
            log.warning("late setpoint %d dropped: it answers state seq %d sampled %.0f ms ago (max_answer_age_s "
                        "%.3f)", n, p.state_seq, (now_ns - sampled_ns) * 1e-6, self.max_answer_age_ns * 1e-9)
        return True

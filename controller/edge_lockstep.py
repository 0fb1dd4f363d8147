"""The edge's lockstep control plane (`LockstepPlane`, a mixin of `sea_hil.controller.edge.EdgeNode`): which released states
the controller must answer before simulated time advances, the wait for their ACKs and setpoints (re-publishing a
state every `resend_ns` of wall time while waiting), and the callback-fed inbox (setpoints, voltages and ACKs in
lockstep; ACKs only in real time) that the wait blocks on instead of polling. It uses the node's `uplink`,
`counters`, `payloads`, `stop_event`, `resend_ns` and `on_downlink`.
"""
from __future__ import annotations

import queue
import time
from collections.abc import Callable
from typing import Any

import zenoh

from sea_hil.protocol.payloads import AckPayload


class LockstepPlane:
    _inbox: queue.SimpleQueue[tuple[bool, bytes, int]]
    _in_flight: Any
    _newest_released: int
    _awaiting: dict[int, bytes]
    _acks: dict[int, AckPayload]
    _seen_setpoints: set[int]
    counters: Any
    uplink: Any
    payloads: Any
    stop_event: Any
    resend_ns: int
    on_downlink: Callable[..., bool]

    def _await_released(self, now: int) -> None:
        """Lockstep: the states the uplink emulator has released by sample time `now` (published by `poll`) are
        the ones the controller must answer before time advances; a state held back by the emulated delay is not
        waited for (the plant runs on meanwhile, as in real time). A state released after a newer one is ignored
        by the controller (as in real time), so it is not awaited but counted (`uplink_out_of_order`)."""
        for seq, data in self._in_flight.pop_due(now):
            if seq <= self._newest_released:
                self.counters.uplink_out_of_order += 1
                continue
            self._newest_released = seq
            self._awaiting[seq] = data

    def _wait_for_controller(self) -> None:
        """Lockstep: block until every state published this step is acknowledged (and its setpoint received)."""
        last_progress = time.monotonic_ns()
        while self._awaiting and not self.stop_event.is_set():
            progressed = self._drain_zenoh()
            for seq in list(self._awaiting):
                ack = self._acks.get(seq)
                if ack is not None and (not ack.sent or ack.setpoint_seq in self._seen_setpoints):
                    del self._awaiting[seq]
                    progressed = True
            now = time.monotonic_ns()
            if progressed:
                last_progress = now
            elif now - last_progress > self.resend_ns:
                for data in self._awaiting.values():    # already through the emulator: straight to the wire
                    self.uplink.republish(data)  # same seq: the controller answers duplicates idempotently
                if self._acks:
                    self.counters.lockstep_resends += 1
                else:   # no ACK yet at all: the controller is still starting up
                    self.counters.lockstep_startup_resends += 1
                last_progress = now
            else:
                try:
                    if self._dispatch(self._inbox.get(timeout=(self.resend_ns - (now - last_progress)) * 1e-9)):
                        last_progress = time.monotonic_ns()
                except queue.Empty:
                    pass

    def _to_inbox(self, is_ack: bool) -> Callable[[zenoh.Sample], None]:
        put = self._inbox.put
        return lambda s: put((is_ack, s.payload.to_bytes(), time.monotonic_ns()))

    def _dispatch(self, item: tuple[bool, bytes, int]) -> bool:
        is_ack, data, rx_ns = item
        return self.on_ack(data) if is_ack else self.on_downlink(data, rx_ns)

    def _drain_zenoh(self) -> bool:
        got = False
        while True:
            try:
                item = self._inbox.get_nowait()
            except queue.Empty:
                return got
            got = self._dispatch(item) or got

    def on_ack(self, data: bytes) -> bool:
        """Handle one payload from the control key (lockstep ACKs); anything else is counted and dropped."""
        p = self.payloads.try_decode(data)
        if p is None:
            return False
        if not isinstance(p, AckPayload):
            self.counters.unexpected_payloads += 1
            return False
        self._acks[p.state_seq] = p
        self._acks.pop(p.state_seq - 1000, None)
        return True

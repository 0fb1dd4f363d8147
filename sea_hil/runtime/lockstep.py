"""All of lockstep in one place: simulated time advances only when every node has handled the step.

- Driver (`LockstepPacer`): it integrates sample k -> k+1 only once the VOLTAGE_CMD answering feedback k (same
  8-bit seq) has arrived for every node it serves; the last feedback is re-sent every `resend_s` of wall time while
  waiting, so a peer that joins late or a lost frame does not stall the session.
- Edge (`LockstepEdgeSync`): the states the uplink emulator has released by the current sample time are the ones
  the controller must answer before time advances (a state held back by the emulated delay is not waited for: the
  plant runs on meanwhile, as in real time); the edge blocks until each is ACKed and the setpoint the ACK names has
  arrived, re-publishing the awaited states every `resend_s` of wall time. Setpoints, voltages and ACKs arrive in one
  callback-fed FIFO (`inbox`) the wait blocks on instead of polling; setpoints enter the downlink emulator at the
  sample they are taken. A re-sent feedback sample already answered is answered again with the same command. The
  edge always commands (the driver waits for it) and never clears faults or detects stream restarts.
- Controller (`LockstepControllerSync`): every state, in order (a FIFO, no newest-only), each answered with an
  `AckPayload` on the control key after its setpoint; a re-sent state it has answered is answered again, the same
  messages (idempotent).
"""
from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable
from typing import Any

import can
import zenoh

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_frames import VoltageCmd
from sea_hil.protocol.canbus import batches
from sea_hil.protocol.link import DelayQueue, release_sample_ns
from sea_hil.protocol.payloads import AckPayload, encode
from sea_hil.protocol.sequence import SeqVerdict
from sea_hil.protocol.zsession import publisher
from sea_hil.queues import timed_get
from sea_hil.runtime.clock import Clock, RealTimeClock, control_payload

log = logging.getLogger("sea_hil.plant")


class LockstepClock(Clock):
    name: str = "lockstep"

    def __init__(self, plant_resend_s: float = 0.05, edge_resend_s: float = 0.1) -> None:
        self.plant_resend_s, self.edge_resend_s = plant_resend_s, edge_resend_s

    def plant(self, node: Any) -> LockstepPacer:
        return LockstepPacer(node, self.plant_resend_s)

    def edge(self, node: Any) -> LockstepEdgeSync:
        return LockstepEdgeSync(node, self.edge_resend_s)

    def controller(self, node: Any) -> LockstepControllerSync:
        return LockstepControllerSync(node)


def clock_for(lockstep: bool) -> Clock:
    """The clock of a session: lockstep (simulated time) or real time."""
    return LockstepClock() if lockstep else RealTimeClock()


class LockstepPacer:
    def __init__(self, node: Any, resend_s: float) -> None:
        self.node = node
        self.resend_ns = int(resend_s * 1e9)
        self.answered: set[int] = set()
        self.done = False
        self.end_seq: int | None = None

    def start(self, duration_s: float | None) -> None:
        # no compiled-kernel warm-up: loading numba (~0.6 s) costs more wall time than it saves in one cycle
        self.end_seq = None if duration_s is None else int(round(duration_s * 1e9 / self.node.period_ns))
        self.done = False

    def _all_answered(self) -> bool:
        return len(self.answered) >= len(self.node.drivers)

    def _publish_all(self) -> None:
        """Every served node's feedback of the current sample. Where the bus `batches` (`FastVirtualBus`, the
        default in-process bus) all frames leave in one send, so each reader (the edge, the recorder's tap) wakes once
        per sample instead of once per frame while the driver still holds the GIL; the frames, their order and
        what each reader receives are the same. The bus-timing model's simulated handle (its clock moves per
        driver) and other buses send frame by frame (`PlantNode.publish`)."""
        n = self.node
        if n.sim is not None or not batches(n.bus):
            for drv in n.drivers.values():
                n.publish(drv, drv.feedback())
            return
        frames: list[can.Message] = []
        for drv in n.drivers.values():
            try:
                frames += n.codec.encode_feedback(drv.feedback(), saturate=True)
            except MalformedFrame as err:   # as `PlantNode.publish`: a diverged (NaN) model, reported
                n.stats.send_failures += 1
                log.error("node %d: feedback not encodable: %s", drv.node_id, err)
        n.send_frames(frames)   # the bus batches (above): one send

    def tick(self) -> None:
        n = self.node
        self.answered.clear()
        self._publish_all()
        while not self._all_answered() and not n.stop_event.is_set():
            before = len(self.answered)
            n.drain_until(time.monotonic_ns() + self.resend_ns, self._all_answered)
            if len(self.answered) == before:   # nothing new within resend_s: re-send what is missing
                for node_id, drv in n.drivers.items():
                    if node_id not in self.answered:
                        n.publish(drv, drv.feedback())
        if n.stop_event.is_set():
            return
        for drv in n.drivers.values():
            drv.last_cmd_ns = drv.sample_t_ns
        n.step_drivers()
        n.stats.ticks += 1
        if n.stats.ticks % n.heartbeat_every == 0:
            n.heartbeats()
        if self.end_seq is not None and n.stats.ticks >= self.end_seq:
            self.done = True

    def on_command(self, frame: object, drv: Any) -> None:
        if isinstance(frame, VoltageCmd) and frame.seq == drv.seq & 0xFF:
            self.answered.add(frame.node_id)


# Lockstep's control messages wait for a full transmission queue rather than being dropped (zenoh's DROP, the real-time
# choice): a run must be complete to be reproducible, and with DROP a slow subscriber (a recorder in the UML guest)
# missed a setpoint another node applied (tests/socketcan/test_session_vcan.py: 2 of 12 guest runs; 0 of 9 with BLOCK)
CONGESTION = zenoh.CongestionControl.BLOCK


class LockstepEdgeSync:
    congestion_control = CONGESTION
    lockstep = True

    def __init__(self, edge: Any, resend_s: float) -> None:
        self.edge = edge
        self.resend_ns = int(resend_s * 1e9)
        self.inbox: queue.SimpleQueue[tuple[str, bytes, int]] = queue.SimpleQueue()   # (key channel, payload, rx_ns)
        self.in_flight: DelayQueue[tuple[int, bytes]] = DelayQueue()   # states held by the uplink emulator
        self.newest_released = 0
        self.awaiting: dict[int, bytes] = {}
        self.acks: dict[int, AckPayload] = {}

    # ---- arrival: everything into the inbox -------------------------------------------------------------------
    def _to_inbox(self, channel: str) -> Callable[[zenoh.Sample], None]:
        put = self.inbox.put
        return lambda s: put((channel, s.payload.to_bytes(), time.monotonic_ns()))

    def downlink_callback(self, channel: str) -> Callable[[zenoh.Sample], None]:
        """The subscriber callback of the edge's downlink key `channel` ("setpoint" | "voltage")."""
        return self._to_inbox(channel)

    def control_callback(self) -> Callable[[zenoh.Sample], None]:
        return self._to_inbox("control")

    def on_ack(self, data: bytes) -> bool:
        """Handle one payload from the control key (ACKs); anything else is counted and dropped."""
        p = control_payload(self.edge.core, data)
        if p is None:
            return False
        self.acks[p.state_seq] = p
        self.acks.pop(p.state_seq - 1000, None)
        return True

    def _dispatch(self, item: tuple[str, bytes, int]) -> bool:
        channel, data, rx_ns = item
        return self.on_ack(data) if channel == "control" else self.edge.on_downlink(data, rx_ns, channel)

    def drain(self) -> bool:
        got = False
        while True:
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                return got
            got = self._dispatch(item) or got

    # ---- the feedback path ------------------------------------------------------------------------------------
    def repeat_feedback(self, fb: Any) -> bool:
        """The driver re-sent a sample already answered: send the same command again."""
        cmd = self.edge.core.last_cmd
        if fb.seq == self.edge.core.last_fb_seq and cmd is not None:
            self.edge.send(cmd)
            return True
        return False

    def state_sent(self, at_ns: int, seq: int, data: bytes) -> None:
        self.in_flight.push(at_ns, (seq, data))

    def state_stamp(self, at_ns: int) -> int:
        """A state's header t_ns on the simulated clock: the sample at which the uplink emulator releases it (the
        first sample at or after its delivery time), i.e. when the controller receives it."""
        return release_sample_ns(at_ns, self.edge.core.period_ns)

    def gate(self, fresh: bool) -> tuple[bool, bool]:
        return True, False

    def late(self, rx_ns: int) -> bool:
        return False      # every sample is answered: simulated time waits for the edge

    def restart_possible(self, timed_out: bool) -> bool:
        return False

    def sync(self, now_ns: int) -> None:
        self._await_released(now_ns)
        self._wait_for_controller()

    def _await_released(self, now: int) -> None:
        """A state released after a newer one is ignored by the controller (as in real time), so it is not awaited
        but counted (`uplink_out_of_order`)."""
        for seq, data in self.in_flight.pop_due(now):
            if seq <= self.newest_released:
                self.edge.core.counters.uplink_out_of_order += 1
                continue
            self.newest_released = seq
            self.awaiting[seq] = data

    def _wait_for_controller(self) -> None:
        """Block until every awaited state is acknowledged (and its setpoint received)."""
        edge, core = self.edge, self.edge.core
        seen = core.intake.seen_setpoints
        last_progress = time.monotonic_ns()
        while self.awaiting and not edge.stop_event.is_set():
            progressed = self.drain()
            for seq in list(self.awaiting):
                ack = self.acks.get(seq)
                if ack is not None and (not ack.sent or ack.setpoint_seq in seen):
                    del self.awaiting[seq]
                    progressed = True
            now = time.monotonic_ns()
            if progressed:
                last_progress = now
            elif now - last_progress > self.resend_ns:
                for data in self.awaiting.values():    # already through the emulator: straight to the wire
                    core.publisher.uplink.republish(data)  # same seq: the controller answers duplicates idempotently
                if self.acks:
                    core.counters.lockstep_resends += 1
                else:   # no ACK yet at all: the controller is still starting up
                    core.counters.lockstep_startup_resends += 1
                last_progress = now
            else:
                try:
                    if self._dispatch(timed_get(self.inbox, (self.resend_ns - (now - last_progress)) * 1e-9)):
                        last_progress = time.monotonic_ns()
                except queue.Empty:
                    pass


class LockstepControllerSync:
    congestion_control = CONGESTION

    def __init__(self, ctrl: Any) -> None:
        self.ctrl = ctrl
        self.ack_pub = publisher(ctrl.session, ctrl.keys.control, congestion_control=CONGESTION)
        self._last_answer: tuple[int, list[tuple[Any, bytes]]] | None = None

    def state_source(self, session: zenoh.Session, key: str) -> FifoStates:
        return FifoStates(session, key)

    def repeat_state(self, verdict: SeqVerdict, seq: int) -> bool:
        """A re-sent state we answered: answer again (the same messages)."""
        if verdict is SeqVerdict.DUPLICATE and self._last_answer and self._last_answer[0] == seq:
            for pub, msg in self._last_answer[1]:
                pub.put(msg)
            return True
        return False

    def answer_extra(self, state_seq: int, setpoint_seq: int, sent: bool) -> list[tuple[Any, bytes]]:
        return [(self.ack_pub, encode(AckPayload(state_seq, time.monotonic_ns(), state_seq,
                                                 setpoint_seq if sent else 0, sent, epoch=self.ctrl.epoch)))]

    def answered(self, seq: int, answer: list[tuple[Any, bytes]]) -> None:
        self._last_answer = (seq, answer)

    def arrival_ns(self, p: Any) -> int:
        """The state's arrival on the simulated clock: the edge stamps it with its release (`state_stamp`)."""
        return int(p.t_ns)

    def restart_possible(self, silent: bool) -> bool:
        return False

    def close(self) -> None:
        self.ack_pub.undeclare()


class FifoStates:
    """Every state, in order: a FIFO fed by the subscriber callback (woken on arrival, no polling)."""
    superseded = 0   # none: every state is read

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self._q: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self._sub = session.declare_subscriber(key, lambda s: self._q.put(s.payload.to_bytes()))

    def recv(self, timeout_s: float) -> bytes | None:
        try:
            return timed_get(self._q, timeout_s)
        except queue.Empty:
            return None

    def close(self) -> None:
        self._sub.undeclare()

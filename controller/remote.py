"""The remote controller node: subscribes to the sampled state, runs the outer ET/TT SMC (its pure core:
`controller/remote_core.py`, state in, messages out; this node does the I/O) and
publishes a setpoint only on events (TT: every sample). With `inner="remote"` it also runs the backstepping law on
the 10 ms state and publishes voltages every sample (to be tunnelled to CAN by the edge, held for 10 ms).

Per handled state it publishes one JSON tracking record on the `event` key (desired vs measured, for recording and
reports; not a control transmission). How it meets the edge is its clock's part (`sync`): in real time the newest
state only; in lockstep every state in order, each ACKed on the `control` key (`sea_hil.runtime.lockstep`). A
heartbeat event is sent when no event fired for `trigger.max_inter_event_s`, so the edge keeps commanding (its
setpoint timeout is twice that).

Time: t = 0 is the start of the measured cycles. With `trajectory.lead_in_s` > 0 the first handled state is at
t = -lead_in_s and the desired motion until t = 0 is the `LeadIn` from that measured state onto the trajectory's start
(tracking records carry negative `t_s` then; the session summary reports the lead-in apart).
"""
from __future__ import annotations

import json
import logging
import time

import zenoh

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.remote_core import ControllerCore
from sea_hil.errors import MalformedPayload
from sea_hil.protocol.epoch import EpochVerdict, PeerEpoch, new_epoch
from sea_hil.protocol.keys import KEY_PAYLOADS, Keys
from sea_hil.protocol.payloads import EventStatePayload, PayloadCounters, StatePayload
from sea_hil.protocol.sequence import SequenceTracker, SeqVerdict
from sea_hil.protocol.zsession import await_subscriber, publisher
from sea_hil.runtime.clock import Clock, ControllerSync, RealTimeClock
from sea_hil.runtime.node import Node

log = logging.getLogger("sea_hil.controller")


class RemoteController(Node):
    kind = "controller"

    def __init__(self, cfg: SeaHilConfig, session: zenoh.Session, mode: str, *, inner: str = "edge",
                 clock: Clock | None = None, cycles: int = 1) -> None:
        super().__init__()
        self.cfg, self.mode, self.inner_mode, self.session = cfg, mode, inner, session
        self.keys = Keys.from_config(cfg.zenoh)
        self.epoch = new_epoch()                    # this controller's session epoch, in every payload it sends
        self.edge_epoch = PeerEpoch("edge", log)    # the state stream's epoch, learned on first contact
        self.core = ControllerCore(cfg, mode, inner, cycles, self.epoch)   # the pure part: state in, messages out
        self.edge_trigger, self.trajectory_id = self.core.edge_trigger, self.core.trajectory_id
        self.trajectory_mismatches = 0
        self.sync: ControllerSync = (clock or RealTimeClock()).controller(self)
        self.source = self.sync.state_source(session, self.keys.state)
        self.sp_pub = publisher(session, self.keys.setpoint, congestion_control=self.sync.congestion_control)
        self.v_pub = publisher(session, self.keys.voltage, congestion_control=self.sync.congestion_control)
        self.event_pub = publisher(session, self.keys.event, express=False,
                                   congestion_control=zenoh.CongestionControl.BLOCK)
        self.payloads = PayloadCounters()
        self.seq = SequenceTracker()
        self.stats_pub = publisher(session, self.keys.stats, express=False)
        self.unexpected_payloads = self.ignored_states = self.edge_restarts = self.unusable_states = 0
        self.restart_gap_ns = int(round(2 * cfg.trigger.max_inter_event_s * 1e9))
        self._last_state_wall_ns: int | None = None
        self._pubs = {"setpoint": self.sp_pub, "voltage": self.v_pub}
        # > 0 (`sea-hil controller --await-recorder S`): a recorder is expected; the first tracking record waits up
        # to this long for it to match the event key (`_await_recorder`)
        self.await_recorder_s = 0.0
        self.recorder_unmatched = 0

    # ---- the core's state, read (and, by tests, set) through the node ----------------------------------------
    states = property(lambda self: self.core.states)
    setpoint_seq = property(lambda self: self.core.setpoint_seq)
    predictor = property(lambda self: self.core.predictor)
    _last_t_ns = property(lambda self: self.core.last_t_ns)
    done = property(lambda self: self.core.done, lambda self, v: setattr(self.core, "done", v))
    t0_ns = property(lambda self: self.core.t0_ns, lambda self, v: setattr(self.core, "t0_ns", v))
    lead_in_ns = property(lambda self: self.core.lead_in_ns)

    # ---- the node hooks -------------------------------------------------------------------------------------------
    def _step(self) -> bool:
        """Handle the next state, if one arrives within 50 ms."""
        data = self.source.recv(0.05)
        if data is None:
            return False
        self.handle(data)
        return True

    def finished(self) -> bool:
        return bool(self.done)

    def _close(self) -> None:
        self.source.close()
        self.sync.close()

    def handle(self, data: bytes, now_ns: int | None = None) -> None:
        """Handle one state payload (`now_ns`: arrival time, default now). Malformed or wrong-type payloads and
        stale/duplicated state seqs are counted (`stats_dict`) and ignored."""
        p = self.payloads.try_decode(data, KEY_PAYLOADS["state"])   # another type: rejected as KEY, counted
        if p is None:
            return
        if not isinstance(p, EventStatePayload if self.edge_trigger else StatePayload) or \
                (not self.edge_trigger and isinstance(p, EventStatePayload)):
            self.unexpected_payloads += 1
            return
        if self.edge_trigger and p.trajectory_id != self.trajectory_id:   # type: ignore[attr-defined]
            self.trajectory_mismatches += 1
            log.error("state %d refused: the edge's trajectory %08x is not the controller's %08x (same [trajectory] "
                      "and CSV on both ends?)", p.seq, p.trajectory_id, self.trajectory_id)  # type: ignore
            return
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        epoch = self.edge_epoch.check(p.epoch, lambda: self._restart_allowed(p, now_ns))
        if epoch is EpochVerdict.REJECTED:
            return
        if epoch is EpochVerdict.RESTART:
            self._edge_restarted(p)
        else:
            verdict = self.seq.feed(self._stream_seq(p))
            if self.sync.repeat_state(verdict, p.seq):
                return
            if verdict is not SeqVerdict.NEW:
                self.ignored_states += 1
                return
        self._last_state_wall_ns = now_ns
        try:
            ans = self.core.on_state(p, self.sync.arrival_ns, time.monotonic_ns)
        except (ArithmeticError, ValueError, MalformedPayload) as err:   # e.g. absurd but finite state values
            self.unusable_states += 1
            log.warning("state %d not usable: %s", p.seq, err)
            return
        if ans is None:
            return
        answer = [(self._pubs[channel], msg) for channel, msg in ans.messages]
        answer += self.sync.answer_extra(p.seq, self.core.setpoint_seq, bool(answer))
        for pub, msg in answer:
            pub.put(msg)
        self.sync.answered(p.seq, answer)
        if ans.record is not None:
            if self.await_recorder_s > 0:
                self._await_recorder()
            self.event_pub.put(json.dumps(ans.record).encode())

    def _await_recorder(self) -> None:
        """Once, before the first tracking record: wait (bounded) for a subscriber of the event key. A controller
        that joins a running session could publish its INITIAL record before the recorder's subscription has reached
        it across a slow link; that record would be lost. A wait that ends unmatched is counted and logged."""
        t0 = time.monotonic()
        matched = await_subscriber(self.event_pub, self.await_recorder_s)
        self.await_recorder_s = 0.0
        if not matched:
            self.recorder_unmatched += 1
            log.warning("no recorder matched the event key %s within the wait: the first tracking record may not be "
                        "recorded", self.keys.event)
        else:
            log.info("a recorder matched the event key after %.3f s", time.monotonic() - t0)

    def _stream_seq(self, p: StatePayload) -> int:
        """The sequence number of the state stream: `event_seq` (consecutive) with the trigger at the edge, else the
        header seq."""
        return p.event_seq if self.edge_trigger else p.seq   # type: ignore[attr-defined]

    def _restart_allowed(self, p: StatePayload, now_ns: int) -> bool:
        """A new edge epoch starts a new state stream only when no state arrived for the restart gap and it looks
        like a fresh sender (stream seq < tracker window)."""
        silent = self._last_state_wall_ns is not None and now_ns - self._last_state_wall_ns > self.restart_gap_ns
        return self.sync.restart_possible(silent) and self._stream_seq(p) < self.seq.window

    def _edge_restarted(self, p: StatePayload) -> None:
        """The edge restarted: a new state stream; the trajectory continues where it stopped."""
        self.seq.restart()
        self.seq.feed(self._stream_seq(p))
        self.core.restart_at(p)
        self.edge_restarts += 1
        log.warning("state stream restarted at seq %d (edge restart)", p.seq)

    def _stats(self) -> dict[str, object]:
        pc = self.payloads.as_dict()
        rejected = pc["rejected"]
        assert isinstance(rejected, dict)
        # node_id: the limb's CAN node id (as its edge's record has it), so a recording of several limbs can tell
        # whose record this is (sea_hil/report/completeness.py)
        return {"node_id": self.cfg.can.node_ids[0], "states_handled": self.states, "setpoints_sent": self.setpoint_seq,
                "payload_accepted": pc["accepted"], "payload_rejected": pc["rejected_total"],
                **{f"payload_rejected_{k}": v for k, v in rejected.items()},
                "unexpected_payloads": self.unexpected_payloads, "ignored_states": self.ignored_states,
                "edge_restarts": self.edge_restarts, "unusable_states": self.unusable_states,
                "trajectory_mismatches": self.trajectory_mismatches, "unanchored_states": self.core.unanchored,
                "prediction_clamped": self.predictor.clamped if self.predictor else 0,
                **{f"state_seq_{k}": v for k, v in self.seq.as_dict().items()},
                "states_superseded": self.source.superseded, "recorder_unmatched": self.recorder_unmatched,
                **self.edge_epoch.as_dict()}

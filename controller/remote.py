"""The remote controller node: subscribes to the sampled state (newest only), runs the outer ET/TT SMC and
publishes a setpoint only on events (TT: every sample). With `inner="remote"` it also runs the backstepping law on
the 10 ms state and publishes voltages every sample (to be tunnelled to CAN by the edge, held for 10 ms).

Per handled state it publishes one JSON tracking record on the `event` key (desired vs measured, for recording and
reports; not a control transmission) and, in lockstep, an ACK on the `control` key. A heartbeat event is sent when
no event fired for `trigger.max_inter_event_s`, so the edge keeps commanding (its setpoint timeout is twice that).

Time: t = 0 is the start of the measured cycles. With `trajectory.lead_in_s` > 0 the first handled state is at
t = -lead_in_s and the desired motion until t = 0 is the `LeadIn` from that measured state onto the trajectory's start
(tracking records carry negative `t_s` then; the session summary reports the lead-in apart).
"""
from __future__ import annotations

import json
import logging
import queue
import threading
import time
from typing import Any

import zenoh

from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.outer import OuterController
from sea_hil.controller.smc import JointState
from sea_hil.controller.trajectory import LeadIn, make_trajectory
from sea_hil.config import SeaHilConfig
from sea_hil.errors import MalformedPayload
from sea_hil.protocol.keys import Keys
from sea_hil.controller.nominal import nominal_params
from sea_hil.protocol.payloads import (AckPayload, PayloadCounters, SeqVerdict, SequenceTracker, SetpointPayload,
                               StatePayload, VoltagePayload, encode)
from sea_hil.protocol.zsession import LatestSubscriber, publisher

log = logging.getLogger("sea_hil.controller")


class RemoteController:
    def __init__(self, cfg: SeaHilConfig, session: zenoh.Session, mode: str, *, inner: str = "edge",
                 lockstep: bool = False, cycles: int = 1) -> None:
        self.cfg, self.mode, self.inner_mode, self.lockstep = cfg, mode, inner, lockstep
        self.keys = Keys.from_config(cfg.zenoh)
        self.params = nominal_params(cfg)
        self.traj = make_trajectory(cfg.trajectory)
        self.outer = OuterController(cfg, self.params, mode)
        self.inner = InnerLoop(cfg, self.params, tuple(cfg.plant.initial_theta_rad), cfg.zenoh.state_period_s)
        self.duration_ns = int(round(self.traj.period_s * cycles * 1e9))
        self.lead_in_ns = int(round(cfg.trajectory.lead_in_s * 1e9))
        self._lead_in: LeadIn | None = None
        # lockstep must see every state: FIFO fed by a callback (woken on arrival, no polling); real time: newest
        # only (ring of depth 1, never a backlog)
        self._states: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self.sub = (session.declare_subscriber(self.keys.state, lambda s: self._states.put(s.payload.to_bytes()))
                    if lockstep else LatestSubscriber(session, self.keys.state))
        self.sp_pub = publisher(session, self.keys.setpoint)
        self.v_pub = publisher(session, self.keys.voltage)
        self.ack_pub = publisher(session, self.keys.control)
        self.event_pub = publisher(session, self.keys.event, express=False,
                                   congestion_control=zenoh.CongestionControl.BLOCK)
        self.payloads = PayloadCounters()
        self.seq = SequenceTracker()
        self.stop_event = threading.Event()
        self.t0_ns: int | None = None
        self.setpoint_seq = 0
        self.states = 0
        self.done = False
        self._last_answer: tuple[int, list[tuple[zenoh.Publisher, bytes]]] | None = None
        self.stats_pub = publisher(session, self.keys.stats, express=False)
        self.unexpected_payloads = self.ignored_states = self.edge_restarts = self.unusable_states = 0
        self.restart_gap_ns = int(round(2 * cfg.trigger.max_inter_event_s * 1e9))
        self._last_state_wall_ns: int | None = None
        self._last_t_ns = 0

    def run(self, timeout_s: float | None = None) -> bool:
        """Handle states until the trajectory's cycles are done (True) or stop/timeout (False)."""
        deadline = None if timeout_s is None else time.monotonic_ns() + int(timeout_s * 1e9)
        while not self.stop_event.is_set() and not self.done:
            data = self._next_state()
            if data is None:
                if deadline is not None and time.monotonic_ns() > deadline:
                    return False
                continue
            self.handle(data)
        return self.done

    def _next_state(self) -> bytes | None:
        """The next state payload, or None when none arrived within 50 ms."""
        if self.lockstep:
            try:
                return self._states.get(timeout=0.05)
            except queue.Empty:
                return None
        sample = self.sub.recv(0.05)
        return None if sample is None else sample.payload.to_bytes()

    def handle(self, data: bytes, now_ns: int | None = None) -> None:
        """Handle one state payload (`now_ns`: arrival time, default now). Malformed or wrong-type payloads and
        stale/duplicated state seqs are counted (`stats_dict`) and ignored."""
        p = self.payloads.try_decode(data)
        if p is None:
            return
        if not isinstance(p, StatePayload):
            self.unexpected_payloads += 1
            return
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        verdict = self.seq.feed(p.seq)
        if verdict is SeqVerdict.DUPLICATE and self.lockstep and self._last_answer and self._last_answer[0] == p.seq:
            for pub, msg in self._last_answer[1]:   # lockstep re-send of a state we answered: answer again
                pub.put(msg)
            return
        if verdict is not SeqVerdict.NEW and not self._edge_restarted(p, now_ns):
            self.ignored_states += 1
            return
        self._last_state_wall_ns = now_ns
        if self.t0_ns is None:
            self.t0_ns = p.sample_t_ns + self.lead_in_ns
            if self.lead_in_ns:
                self._lead_in = LeadIn(p.theta_rad, p.omega_rad_s, self.traj.sample(0.0), self.lead_in_ns * 1e-9)
        t_ns = p.sample_t_ns - self.t0_ns
        self._last_t_ns = t_ns
        if t_ns > self.duration_ns:
            self.done = True
            return
        try:
            answer, sp, ds = self._answer(p, t_ns)
        except (ArithmeticError, ValueError, MalformedPayload) as err:   # e.g. absurd but finite state values
            self.unusable_states += 1
            log.warning("state %d not usable: %s", p.seq, err)
            return
        self.states += 1
        sent = bool(answer)
        if self.lockstep:
            answer.append((self.ack_pub, encode(AckPayload(p.seq, time.monotonic_ns(), p.seq,
                                                           self.setpoint_seq if sent else 0, sent))))
        for pub, msg in answer:
            pub.put(msg)
        self._last_answer = (p.seq, answer)
        self.event_pub.put(json.dumps({
            "t_s": t_ns * 1e-9, "state_seq": p.seq,
            "theta1_rad": p.theta_rad[0], "theta2_rad": p.theta_rad[1],
            "theta1_d_rad": ds.theta_rad[0], "theta2_d_rad": ds.theta_rad[1],
            "event": sp is not None, "reason": sp.reason.name if sp is not None else "",
            "setpoint_seq": self.setpoint_seq if sent else 0}).encode())

    def _answer(self, p: StatePayload, t_ns: int) -> tuple[list[tuple[zenoh.Publisher, bytes]], Any, Any]:
        """Outer (and, remote placement, inner) control for one new state: the messages to publish."""
        ds = self._lead_in.sample(t_ns * 1e-9) if t_ns < 0 and self._lead_in else self.traj.sample(t_ns * 1e-9)
        js = JointState(p.theta_rad, p.omega_rad_s)
        sp = self.outer.step(t_ns, p.seq, js, ds)
        answer: list[tuple[zenoh.Publisher, bytes]] = []
        if sp is not None:
            self.setpoint_seq += 1
            self.inner.hold(sp.deflection_m, sp.sliding)
            if self.inner_mode == "edge":
                answer.append((self.sp_pub, encode(SetpointPayload(self.setpoint_seq, time.monotonic_ns(), p.seq,
                                                                   sp.deflection_m, sp.sliding, sp.reason))))
        if self.inner_mode == "remote":
            m = (*p.theta_rad, *p.omega_rad_s, *p.delta_m, *p.nut_vel_m_s)
            u = self.inner.voltage(m)  # type: ignore[arg-type]
            self.setpoint_seq += 1
            answer.append((self.v_pub, encode(VoltagePayload(self.setpoint_seq, time.monotonic_ns(), p.seq, u))))
        return answer, sp, ds

    def _edge_restarted(self, p: StatePayload, now_ns: int) -> bool:
        """A not-newer state seq starts a new state stream only when no state arrived for the restart gap and it
        looks like a fresh sender (seq < tracker window); the trajectory then continues where it stopped."""
        silent = self._last_state_wall_ns is not None and now_ns - self._last_state_wall_ns > self.restart_gap_ns
        if self.lockstep or not silent or p.seq >= self.seq.window:
            return False
        self.seq.restart()
        self.seq.feed(p.seq)
        self.t0_ns = p.sample_t_ns - self._last_t_ns
        self.edge_restarts += 1
        log.warning("state stream restarted at seq %d (edge restart)", p.seq)
        return True

    def stats_dict(self) -> dict[str, object]:
        """Counters of this node (published on the stats key by `publish_stats`)."""
        pc = self.payloads.as_dict()
        return {"node": "controller", "states_handled": self.states, "setpoints_sent": self.setpoint_seq,
                "payload_accepted": pc["accepted"], "payload_rejected": pc["rejected_total"],
                **{f"payload_rejected_{k}": v for k, v in pc["rejected"].items()},  # type: ignore[union-attr]
                "unexpected_payloads": self.unexpected_payloads, "ignored_states": self.ignored_states,
                "edge_restarts": self.edge_restarts, "unusable_states": self.unusable_states,
                **{f"state_seq_{k}": v for k, v in self.seq.as_dict().items()}}

    def publish_stats(self, final: bool = False) -> None:
        self.stats_pub.put(json.dumps({**self.stats_dict(), "final": final}).encode())

    def close(self) -> None:
        if isinstance(self.sub, LatestSubscriber):
            self.sub.close()
        else:
            self.sub.undeclare()

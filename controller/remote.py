"""The remote controller node: subscribes to the sampled state, runs the outer ET/TT SMC and
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
from typing import Any

import zenoh

from sea_hil.controller.edge_events import tracking_record
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.outer import OuterController, Setpoint
from sea_hil.controller.predictor import Predictor
from sea_hil.controller.smc import JointState, smc_deflection
from sea_hil.controller.trajectory import LeadIn, make_trajectory, trajectory_id
from sea_hil.config import SeaHilConfig
from sea_hil.errors import MalformedPayload
from sea_hil.protocol.keys import Keys
from sea_hil.controller.nominal import nominal_params
from sea_hil.protocol.payloads import (EventStatePayload, PayloadCounters, SeqVerdict, SequenceTracker,
                                       SetpointPayload, StatePayload, VoltagePayload, encode)
from sea_hil.protocol.zsession import publisher
from sea_hil.runtime.clock import Clock, RealTimeClock
from sea_hil.runtime.node import Node

log = logging.getLogger("sea_hil.controller")


class RemoteController(Node):
    kind = "controller"

    def __init__(self, cfg: SeaHilConfig, session: zenoh.Session, mode: str, *, inner: str = "edge",
                 clock: Clock | None = None, cycles: int = 1) -> None:
        super().__init__()
        self.cfg, self.mode, self.inner_mode, self.session = cfg, mode, inner, session
        self.keys = Keys.from_config(cfg.zenoh)
        self.params = nominal_params(cfg)
        self.traj = make_trajectory(cfg.trajectory)
        self.outer = OuterController(cfg, self.params, mode)
        self.inner = InnerLoop(cfg, self.params, tuple(cfg.plant.initial_theta_rad), cfg.controller.sample_period_s)
        # issue 16: the trigger at the edge (answer every EVENT_STATE) and the predictor of the edge's closed loop
        self.edge_trigger = cfg.trigger.placement == "edge"
        self.trajectory_id = trajectory_id(cfg.trajectory)
        self.predictor: Predictor | None = None
        if cfg.controller.compensation == "predict":
            period_s = 1.0 / cfg.can.feedback_rate_hz
            edge_inner = InnerLoop(cfg, self.params, tuple(cfg.plant.initial_theta_rad), period_s)
            self.predictor = Predictor.for_inner(edge_inner, int(round(period_s * 1e9)), cfg.sim.substeps)
            self.predictor.warm(tuple(cfg.plant.initial_theta_rad))
        self.trajectory_mismatches = 0
        self.duration_ns = int(round(self.traj.period_s * cycles * 1e9))
        self.lead_in_ns = int(round(cfg.trajectory.lead_in_s * 1e9))
        self._lead_in: LeadIn | None = None
        self.sync = (clock or RealTimeClock()).controller(self)
        self.source = self.sync.state_source(session, self.keys.state)
        self.sp_pub = publisher(session, self.keys.setpoint)
        self.v_pub = publisher(session, self.keys.voltage)
        self.event_pub = publisher(session, self.keys.event, express=False,
                                   congestion_control=zenoh.CongestionControl.BLOCK)
        self.payloads = PayloadCounters()
        self.seq = SequenceTracker()
        self.t0_ns: int | None = None
        self.setpoint_seq = 0
        self.states = 0
        self.done = False
        self.stats_pub = publisher(session, self.keys.stats, express=False)
        self.unexpected_payloads = self.ignored_states = self.edge_restarts = self.unusable_states = 0
        self.restart_gap_ns = int(round(2 * cfg.trigger.max_inter_event_s * 1e9))
        self._last_state_wall_ns: int | None = None
        self._last_t_ns = 0

    # ---- the node hooks -------------------------------------------------------------------------------------------
    def _step(self) -> bool:
        """Handle the next state, if one arrives within 50 ms."""
        data = self.source.recv(0.05)
        if data is None:
            return False
        self.handle(data)
        return True

    def finished(self) -> bool:
        return self.done

    def _close(self) -> None:
        self.source.close()
        self.sync.close()

    def handle(self, data: bytes, now_ns: int | None = None) -> None:
        """Handle one state payload (`now_ns`: arrival time, default now). Malformed or wrong-type payloads and
        stale/duplicated state seqs are counted (`stats_dict`) and ignored."""
        p = self.payloads.try_decode(data)
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
        verdict = self.seq.feed(p.event_seq if self.edge_trigger else p.seq)  # type: ignore[attr-defined]
        if self.sync.repeat_state(verdict, p.seq):
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
        answer += self.sync.answer_extra(p.seq, self.setpoint_seq, sent)
        for pub, msg in answer:
            pub.put(msg)
        self.sync.answered(p.seq, answer)
        if not self.edge_trigger:      # with the trigger at the edge, the edge records every outer sample
            self.event_pub.put(json.dumps(tracking_record(t_ns, p.seq, p.theta_rad, ds, sp.reason if sp else None,
                                                          self.setpoint_seq if sent else 0)).encode())

    def _desired(self, t_ns: int) -> Any:
        return self._lead_in.sample(t_ns * 1e-9) if t_ns < 0 and self._lead_in else self.traj.sample(t_ns * 1e-9)

    def _decide(self, p: StatePayload, t_ns: int) -> tuple[Setpoint | None, int]:
        """The setpoint for state p (None: no event) and the arrival time used; with `predict` for the state
        predicted at the instant the setpoint will act (controller/predictor.py), as the offline engine does."""
        js, t_eval, now = JointState(p.theta_rad, p.omega_rad_s), t_ns, 0
        if self.predictor is not None:
            now = self.sync.arrival_ns(p)
            self.predictor.observe_uplink(now - p.sample_t_ns)
            apply_ns = self.predictor.apply_time_ns(now)
            js = self.predictor.predict((p.theta_rad, p.omega_rad_s, p.delta_m, p.nut_vel_m_s), p.sample_t_ns,
                                        apply_ns)
            t_eval = apply_ns - self.t0_ns  # type: ignore[operator]
        ds_eval = self._desired(t_eval)
        if not self.edge_trigger:
            return self.outer.step(t_eval, p.seq, js, ds_eval), now
        cc = self.cfg.controller
        vx, s = smc_deflection(js, ds_eval, self.params, cc.c, cc.rho, cc.boundary_layer)
        return Setpoint(vx, s, p.reason, p.seq, t_eval), now  # type: ignore[attr-defined]

    def _answer(self, p: StatePayload, t_ns: int) -> tuple[list[tuple[zenoh.Publisher, bytes]], Any, Any]:
        """Outer (and, remote placement, inner) control for one new state: the messages to publish."""
        ds = self._desired(t_ns)
        sp, now = self._decide(p, t_ns)
        answer: list[tuple[zenoh.Publisher, bytes]] = []
        if sp is not None:
            self.setpoint_seq += 1
            self.inner.hold(sp.deflection_m, sp.sliding)
            if self.predictor is not None:
                self.predictor.sent(self.predictor.apply_time_ns(now), sp.deflection_m, sp.sliding)
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
        if not self.sync.restart_possible(silent) or p.seq >= self.seq.window:
            return False
        self.seq.restart()
        self.seq.feed(p.seq)
        self.t0_ns = p.sample_t_ns - self._last_t_ns
        self.edge_restarts += 1
        log.warning("state stream restarted at seq %d (edge restart)", p.seq)
        return True

    def _stats(self) -> dict[str, object]:
        pc = self.payloads.as_dict()
        return {"states_handled": self.states, "setpoints_sent": self.setpoint_seq,
                "payload_accepted": pc["accepted"], "payload_rejected": pc["rejected_total"],
                **{f"payload_rejected_{k}": v for k, v in pc["rejected"].items()},  # type: ignore[union-attr]
                "unexpected_payloads": self.unexpected_payloads, "ignored_states": self.ignored_states,
                "edge_restarts": self.edge_restarts, "unusable_states": self.unusable_states,
                "trajectory_mismatches": self.trajectory_mismatches,
                "prediction_clamped": self.predictor.clamped if self.predictor else 0,
                **{f"state_seq_{k}": v for k, v in self.seq.as_dict().items()}}

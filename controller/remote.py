"""The remote controller node: subscribes to the sampled state (newest only), runs the outer ET/TT SMC and
publishes a setpoint only on events (TT: every sample). With `inner="remote"` it also runs the backstepping law on
the 10 ms state and publishes voltages every sample (to be tunnelled to CAN by the edge, held for 10 ms).

Per handled state it publishes one JSON tracking record on the `event` key (desired vs measured, for recording and
reports; not a control transmission) and, in lockstep, an ACK on the `control` key. A heartbeat event is sent when
no event fired for `trigger.max_inter_event_s`, so the edge keeps commanding (its setpoint timeout is twice that).
"""
from __future__ import annotations

import json
import logging
import threading
import time

import zenoh

from controller.inner import InnerLoop
from controller.outer import OuterController
from controller.smc import JointState
from controller.trajectory import make_trajectory
from protocol.config import SeaHilConfig
from protocol.keys import Keys
from protocol.mechanics import limb_params
from protocol.payloads import (AckPayload, PayloadCounters, SeqVerdict, SequenceTracker, SetpointPayload,
                               StatePayload, VoltagePayload, encode)
from protocol.zsession import publisher

log = logging.getLogger("sea_hil.controller")


class RemoteController:
    def __init__(self, cfg: SeaHilConfig, session: zenoh.Session, mode: str, *, inner: str = "edge",
                 lockstep: bool = False, cycles: int = 1) -> None:
        self.cfg, self.mode, self.inner_mode, self.lockstep = cfg, mode, inner, lockstep
        self.keys = Keys.from_config(cfg.zenoh)
        self.params = limb_params(cfg.plant)
        self.traj = make_trajectory(cfg.trajectory)
        self.outer = OuterController(cfg, self.params, mode)
        self.inner = InnerLoop(cfg, self.params, tuple(cfg.plant.initial_theta_rad))
        self.duration_ns = int(round(self.traj.period_s * cycles * 1e9))
        # lockstep must see every state: FIFO; real time: newest only (ring of depth 1, never a backlog)
        handler = zenoh.handlers.FifoChannel(4096) if lockstep else zenoh.handlers.RingChannel(1)
        self.sub = session.declare_subscriber(self.keys.state, handler)
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

    def run(self, timeout_s: float | None = None) -> bool:
        """Handle states until the trajectory's cycles are done (True) or stop/timeout (False)."""
        deadline = None if timeout_s is None else time.monotonic_ns() + int(timeout_s * 1e9)
        while not self.stop_event.is_set() and not self.done:
            sample = self.sub.try_recv()
            if sample is None:
                if deadline is not None and time.monotonic_ns() > deadline:
                    return False
                time.sleep(100e-6)
                continue
            self.handle(sample.payload.to_bytes())
        return self.done

    def handle(self, data: bytes) -> None:
        p = self.payloads.try_decode(data)
        if not isinstance(p, StatePayload):
            return
        verdict = self.seq.feed(p.seq)
        if verdict is SeqVerdict.DUPLICATE and self._last_answer and self._last_answer[0] == p.seq:
            for pub, msg in self._last_answer[1]:   # lockstep re-send of a state we answered: answer again
                pub.put(msg)
            return
        if verdict is not SeqVerdict.NEW:
            return
        if self.t0_ns is None:
            self.t0_ns = p.sample_t_ns
        t_ns = p.sample_t_ns - self.t0_ns
        if t_ns > self.duration_ns:
            self.done = True
            return
        self.states += 1
        ds = self.traj.sample(t_ns * 1e-9)
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

    def close(self) -> None:
        self.sub.undeclare()

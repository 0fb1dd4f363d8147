"""The sample loop of the offline session engine (`sea_hil.offline.session_engine.run_engine`), with the trigger
placements and delay compensation of issue 16.

- `placement="controller"` (the paper's): the edge publishes every outer sample, the controller's trigger decides;
  this path is the lockstep session bit for bit.
- `placement="edge"`: the edge's `EdgeEventGenerator` decides which samples cross the uplink (checked every outer
  sample, or every 1 kHz sample with `edge_check="sample"`), the controller answers each state. State seqs are then
  the 1 kHz sample index + 1 (gaps are normal), tracking records are the edge's, one per outer sample.
- `compensation="predict"`: the controller answers with v_x for the state predicted at the instant its setpoint will
  act (`sea_hil.controller.predictor`); the trigger (controller placement) sees the predicted state too.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import json

from sea_hil.controller.edge_events import EdgeEvents
from sea_hil.controller.remote_core import ControllerCore
from sea_hil.protocol.link import DelayQueue
from sea_hil.protocol.payloads import EventStatePayload, SetpointPayload, StatePayload


@dataclass(frozen=True)
class EngineOptions:
    placement: str = "controller"       # controller | edge
    compensation: str = "none"          # none | predict
    edge_check: str = "outer"           # outer | sample: how often the edge evaluates its trigger
    edge_model: bool = False            # the edge's lookahead runs the nominal model (else: extrapolation)

    def __post_init__(self) -> None:
        if self.placement not in ("controller", "edge") or self.compensation not in ("none", "predict") \
                or self.edge_check not in ("outer", "sample"):
            raise ValueError(f"bad engine options {self}")

    @classmethod
    def from_config(cls, cfg: Any) -> "EngineOptions":
        """The options a config selects (`trigger.placement`, `trigger.edge_check`, `trigger.edge_model`,
        `controller.compensation`)."""
        t = cfg.trigger
        return cls(placement=t.placement, compensation=cfg.controller.compensation, edge_check=t.edge_check,
                   edge_model=t.edge_model)


def _stamp(p: StatePayload) -> int:
    """A state's arrival on the simulated clock: its header stamp (the release sample, `LockstepEdgeSync.state_stamp`)."""
    return p.t_ns


class SessionLoop:
    """State of one offline session: the live controller's core (`ControllerCore`) behind the emulated links, the
    edge's event core (`EdgeEvents`) with the trigger at the edge. Built and stepped by `run_session`."""

    def __init__(self, env: Any, opts: EngineOptions, cycles: int) -> None:
        self.e, self.o = env, opts
        self.core = ControllerCore(env.cfg, env.mode, cycles=cycles)
        self.in_flight: DelayQueue[StatePayload] = DelayQueue()
        self.pending_down: DelayQueue[SetpointPayload] = DelayQueue()
        self.state_seq = self.newest = 0
        self.sampled_at: dict[int, int] = {}    # state seq -> sample time (the edge's late-answer check)
        self.max_answer_age_ns = int(round(env.cfg.safety.setpoint.max_answer_age_s * 1e9))
        self.edge: EdgeEvents | None = None     # the live edge's core (controller/edge_events.py)
        if opts.placement == "edge":
            self.edge = EdgeEvents(env.cfg, env.mode, env.inner, env.period_ns, env.outer_every,
                                   every_sample=opts.edge_check == "sample",
                                   model=opts.edge_model and opts.compensation == "predict", jit=env.jit,
                                   duration_ns=env.duration_ns)

    # ---- edge ---------------------------------------------------------------------------------------------------
    def edge_sample(self, k: int, fb: tuple) -> None:
        """The edge's work for sample k before the controller's answers: publish a state (placement rules)."""
        e, now = self.e, k * self.e.period_ns
        if self.edge is None:
            if k % e.outer_every == 0:
                self.state_seq += 1
                self._publish(self.state_seq, now, fb, None)
            return
        d = self.edge.on_sample(now, fb)
        if d is None:
            return
        if d.reason is not None:
            self._publish(d.seq, now, fb, d)
        if d.hold is not None:                     # the local fallback of a silent downlink (as the live edge)
            e.inner.hold(*d.hold)
        if d.record is not None:
            e.rec.tracking(d.record, now)

    def _publish(self, seq: int, now: int, fb: tuple, d: Any) -> None:
        self.sampled_at[seq] = now
        self.sampled_at.pop(seq - 100_000, None)
        at = self.e.uplink.submit(now, self.e.state_bytes)
        if at is None:
            return
        stamp = -(-at // self.e.period_ns) * self.e.period_ns
        if d is None:
            p = StatePayload(seq, stamp, now, *fb)
        else:
            p = EventStatePayload(seq, stamp, now, *fb, d.event_seq, d.reason, self.edge.trajectory_id)  # type: ignore
        self.in_flight.push(at, p)

    def take_downlink(self, now: int) -> None:
        for payload in self.pending_down.pop_due(now):
            sampled = self.sampled_at.get(payload.state_seq)
            if self.max_answer_age_ns and sampled is not None and now - sampled > self.max_answer_age_ns:
                continue                               # a late answer: the live edge drops it (controller/edge_core.py)
            self.e.inner.hold(payload.deflection_m, payload.sliding)
            if self.edge is not None:
                self.edge.answered(payload.state_seq, now)

    # ---- controller ----------------------------------------------------------------------------------------------
    def controller(self, now: int) -> bool:
        """Answer the states released by `now` with the live controller's core (`ControllerCore`, stamped with the
        release sample as lockstep stamps them); False when the controller has finished its cycles."""
        e, core = self.e, self.core
        for p in self.in_flight.pop_due(now):
            if p.seq <= self.newest:                     # released after a newer one: the controller ignores it
                continue
            self.newest = p.seq
            e.rec.state(p.seq, p.sample_t_ns, (p.theta_rad, p.omega_rad_s, p.delta_m, p.nut_vel_m_s), now)
            ans = core.on_state(p, _stamp, lambda: now)
            if ans is None:
                return False
            sp = ans.setpoint
            if sp is not None:
                payload = SetpointPayload(core.setpoint_seq, now, p.seq, sp.deflection_m, sp.sliding, sp.reason)
                e.rec.setpoint(payload, now)
                # the edge's intake: the envelope first (a rejected setpoint never enters the downlink emulator)
                if e.envelope.admit(payload.seq, payload.deflection_m):
                    at = e.downlink.submit(now, e.setpoint_bytes)
                    if at is not None:
                        self.pending_down.push(at, payload)
            if ans.record is not None:
                e.rec.tracking(json.loads(ans.record), now)
        return True

    def next_k(self, k: int) -> int:
        """The next sample after k at which something happens."""
        e = self.e
        if self.edge is not None and self.o.edge_check == "sample":
            return k + 1
        nxt = min((k // e.outer_every + 1) * e.outer_every, e.n_max)
        for due in (self.in_flight.next_due_ns(), self.pending_down.next_due_ns()):
            if due is not None and due < nxt * e.period_ns:
                nxt = max(k + 1, -(-due // e.period_ns))
        return nxt

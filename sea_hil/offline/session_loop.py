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

from sea_hil.controller.edge_events import EdgeEvents
from sea_hil.controller.outer import Setpoint
from sea_hil.controller.smc import JointState, smc_deflection
from sea_hil.protocol.link import DelayQueue
from sea_hil.protocol.payloads import SetpointPayload, TriggerReason


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
    def from_config(cls, cfg: Any) -> EngineOptions:
        """The options a config selects (`trigger.placement`, `trigger.edge_check`, `trigger.edge_model`,
        `controller.compensation`)."""
        t = cfg.trigger
        return cls(placement=t.placement, compensation=cfg.controller.compensation, edge_check=t.edge_check,
                   edge_model=t.edge_model)


class SessionLoop:
    """State of one offline session; `run()` steps it to the end. Built by `run_engine`."""

    def __init__(self, env: Any, opts: EngineOptions) -> None:
        self.e, self.o = env, opts
        self.in_flight: DelayQueue[tuple[int, int, tuple, Any]] = DelayQueue()
        self.pending_down: DelayQueue[SetpointPayload] = DelayQueue()
        self.state_seq = self.setpoint_seq = self.newest = 0
        self.sampled_at: dict[int, int] = {}    # state seq -> sample time (the edge's late-answer check)
        self.max_answer_age_ns = int(round(env.cfg.safety.setpoint.max_answer_age_s * 1e9))
        self.t0_ns: int | None = None
        self.lead: Any = None
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
            self._publish(d.seq, now, fb, d.reason)
        if d.hold is not None:                     # the local fallback of a silent downlink (as the live edge)
            e.inner.hold(*d.hold)
        if d.record is not None:
            e.rec.tracking(d.record, now)

    def _publish(self, seq: int, now: int, fb: tuple, reason: Any) -> None:
        self.sampled_at[seq] = now
        self.sampled_at.pop(seq - 100_000, None)
        at = self.e.uplink.submit(now, self.e.state_bytes)
        if at is not None:
            self.in_flight.push(at, (seq, now, fb, reason))

    def take_downlink(self, now: int) -> None:
        for payload in self.e.downlink_due(self.pending_down, now):
            sampled = self.sampled_at.get(payload.state_seq)
            if self.max_answer_age_ns and sampled is not None and now - sampled > self.max_answer_age_ns:
                continue                               # a late answer: the live edge drops it (edge_downlink.py)
            self.e.inner.hold(payload.deflection_m, payload.sliding)
            if self.edge is not None:
                self.edge.answered(payload.state_seq, now)

    # ---- controller ---------------------------------------------------------------------------------------------
    def controller(self, now: int) -> bool:
        """Answer the states released by `now`; False when the controller has finished its cycles."""
        e = self.e
        for seq, sample_ns, fb, edge_reason in self.in_flight.pop_due(now):
            if seq <= self.newest:                     # released after a newer one: the controller ignores it
                continue
            self.newest = seq
            e.rec.state(seq, sample_ns, fb, now)
            # t counts from the first state (the paper's placement) or the edge's anchor, its latest INITIAL state
            if edge_reason is TriggerReason.INITIAL or (self.t0_ns is None and self.edge is None):
                self.t0_ns = sample_ns + e.lead_in_ns
                self.lead = e.lead_in(fb) if e.lead_in_ns else None
            elif self.t0_ns is None:       # no anchor yet (its state was lost): as the live controller, no answer
                continue
            t_ns = sample_ns - self.t0_ns
            if t_ns > e.duration_ns:
                return False
            ds = self._desired(t_ns)
            sp = self._answer(seq, sample_ns, fb, now, t_ns, ds, edge_reason)
            if sp is not None:
                self.setpoint_seq += 1
                payload = SetpointPayload(self.setpoint_seq, now, seq, sp.deflection_m, sp.sliding, sp.reason)
                e.rec.setpoint(payload, now)
                # the edge's intake: the envelope first (a rejected setpoint never enters the downlink emulator)
                if e.envelope.admit(payload.seq, payload.deflection_m):
                    at = e.downlink.submit(now, e.setpoint_bytes)
                    if at is not None:
                        self.pending_down.push(at, payload)
                if e.predictor is not None:
                    e.predictor.sent(e.predictor.apply_time_ns(now), sp.deflection_m, sp.sliding)
            if self.edge is None:
                e.rec.tracking(e.tracking_record(t_ns, seq, fb[0], ds, sp.reason if sp else None,
                                                 self.setpoint_seq if sp else 0), now)
        return True

    def _desired(self, t_ns: int) -> Any:
        return self.lead.sample(t_ns * 1e-9) if t_ns < 0 and self.lead else self.e.traj.sample(t_ns * 1e-9)

    def _answer(self, seq: int, sample_ns: int, fb: tuple, now: int, t_ns: int, ds: Any,
                edge_reason: Any) -> Setpoint | None:
        e = self.e
        js, t_eval, ds_eval = JointState(fb[0], fb[1]), t_ns, ds
        if e.predictor is not None:
            e.predictor.observe_uplink(now - sample_ns)
            apply_ns = e.predictor.apply_time_ns(now)
            js = e.predictor.predict(fb, sample_ns, apply_ns)
            t_eval = apply_ns - self.t0_ns
            ds_eval = self._desired(t_eval)
        if self.edge is None:
            return e.outer.step(t_eval, seq, js, ds_eval)
        vx, s = smc_deflection(js, ds_eval, e.params, e.c, e.rho, e.boundary_layer)
        return Setpoint(vx, s, edge_reason, seq, t_eval)

    def next_k(self, k: int) -> int:
        """The next sample after k at which something happens."""
        e = self.e
        if self.edge is not None and self.edge.every_sample:
            return k + 1
        nxt = min((k // e.outer_every + 1) * e.outer_every, e.n_max)
        for due in (self.in_flight.next_due_ns(), self.pending_down.next_due_ns()):
            if due is not None and due < nxt * e.period_ns:
                nxt = max(k + 1, -(-due // e.period_ns))
        return nxt

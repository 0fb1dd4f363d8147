"""The trigger at the edge in the live edge node (issue 16, `trigger.placement = "edge"`): a pure core around the
sensor-side event generator (`EdgeEventGenerator`). Per feedback sample it says whether to publish an EVENT_STATE
(and with which body fields) and gives the tracking record of each outer sample (the edge sees every sample, the
controller only the events); `answered` tells it about an applied setpoint. No I/O: the edge node publishes.

The offline session engine runs this same core (inside `EdgeCore`, `sea_hil.offline.session_engine`):
checks every outer sample (or every 1 kHz sample, `trigger.edge_check = "sample"`; TT: every outer sample whatever
`edge_check`, and every one is published, answers in flight or not: issue 29), state seq = sample index + 1,
the lookahead on the nominal model (`trigger.edge_model`, with `controller.compensation = "predict"`: the engine
builds that model only then) with the setpoint the edge holds kept; the trajectory anchor (an INITIAL state) is
re-published until the controller answers it (controller/edge_trigger.py).

The local fallback (`trigger.edge_fallback = "local"`, docs/deviations.md section 17): while an answer is overdue
(`EdgeEventGenerator.overdue`: a silent or bursty downlink, a lost state) the edge computes v_x itself at every
checked sample from the SMC law on its own fresh sample (the nominal model, x_d(t) of the trajectory it already has)
and returns it as `EdgeDecision.hold`, which the caller holds in the inner loop until the controller's next setpoint;
`"hold"` keeps the controller's last setpoint (zero-order hold, the behaviour before). Bounded in time by the edge's
setpoint timeout, which only the controller's setpoints refresh. A local setpoint outside the setpoint envelope is
not held (counted).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_trigger import EdgeEventGenerator
from sea_hil.controller.envelope import SetpointEnvelope, admissible
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.predictor import Predictor
from sea_hil.controller.smc import JointState, smc_deflection
from sea_hil.controller.trajectory import make_trajectory, trajectory_id
from sea_hil.controller.trigger import EventTrigger, TimeTrigger, error_threshold
from sea_hil.protocol.payloads import TriggerReason


@dataclass(frozen=True)
class EdgeDecision:
    seq: int                              # the state seq of this sample (sample index + 1)
    reason: TriggerReason | None          # publish this sample (None: not an event)
    event_seq: int                        # EVENT_STATE.event_seq if published
    record: dict[str, Any] | None         # the tracking record of an outer sample, else None
    hold: tuple[tuple[float, float], tuple[float, float]] | None = None   # local fallback (v_x, s) to hold


def make_trigger(cfg: SeaHilConfig, mode: str) -> EventTrigger | TimeTrigger:
    tc, cc = cfg.trigger, cfg.controller
    if mode == "tt":
        return TimeTrigger()
    return EventTrigger(error_threshold(tc.eta, tc.lipschitz_l, cc.c), tc.r, int(round(tc.max_inter_event_s * 1e9)))


class EdgeEvents:
    def __init__(self, cfg: SeaHilConfig, mode: str, inner: Any, period_ns: int, outer_every: int, *,
                 every_sample: bool | None = None, model: bool | None = None, jit: bool = True,
                 duration_ns: int | None = None) -> None:
        """`every_sample` (check every 1 kHz sample) and `model` (model lookahead) default to the config's
        (`trigger.edge_check`, `trigger.edge_model` with `controller.compensation = "predict"`); `duration_ns`, the
        measured cycles (default `sim.cycles` trajectory periods): no tracking record after them (the controller
        has stopped answering; in real time the session's shut-down would otherwise be counted as tracking)."""
        traj = make_trajectory(cfg.trajectory)
        self.duration_ns = int(round(traj.period_s * cfg.sim.cycles * 1e9)) if duration_ns is None else duration_ns
        heartbeat_ns = int(round(cfg.trigger.max_inter_event_s * 1e9))
        # re-anchor when the anchor is unanswered for a heartbeat period, or after the setpoint timeout (twice that)
        self.generator = EdgeEventGenerator(make_trigger(cfg, mode), traj, int(round(cfg.trajectory.lead_in_s * 1e9)),
                                            cfg.trajectory.lead_in_max_velocity_rad_s,
                                            anchor_timeout_ns=heartbeat_ns, reanchor_after_ns=2 * heartbeat_ns,
                                            max_timeout_ns=int(round(cfg.safety.setpoint.max_answer_age_s * 1e9)))
        self.trajectory_id = trajectory_id(cfg.trajectory)
        self.inner, self.period_ns, self.outer_every = inner, period_ns, outer_every
        self.every_sample = cfg.trigger.edge_check == "sample" if every_sample is None else every_sample
        if model is None:
            model = cfg.trigger.edge_model and cfg.controller.compensation == "predict"
        if mode == "tt":    # a time trigger has nothing to evaluate between outer samples, nor a lookahead to run
            self.every_sample, model = False, False
        self.model: Predictor | None = None
        if model:
            self.model = Predictor.for_inner(inner, period_ns, cfg.sim.substeps, jit=jit)
            self.model.warm(cfg.plant.initial_theta_rad)
        self.events = 0
        self.resume_anchors = 0
        self.sampled_at: dict[int, int] = {}
        self.fallback = cfg.trigger.edge_fallback == "local"
        cc = cfg.controller
        self._smc = (nominal_params(cfg), cc.c, cc.rho, cc.boundary_layer)
        self._envelope = SetpointEnvelope.from_config(cfg.safety.setpoint).deflection_max_m
        self.fallback_samples = 0         # checked samples at which the edge held its own v_x
        self.fallback_episodes = 0        # overdue periods (each one a run of fallback samples)
        self.fallback_rejected = 0        # local setpoints outside the envelope (not held)
        self._in_fallback = False
        self.max_stale_ns = 0             # longest run on a setpoint older than the oldest unanswered state
        self.max_stale_excess_ns = 0      # ... beyond the answer timeout at that sample
        self._last_hold_ns: int | None = None   # the sample the held setpoint was computed for (answered or local)

    def on_sample(self, sample_ns: int, fb: tuple[tuple[float, float], ...]) -> EdgeDecision | None:
        """fb = (theta, omega, delta, nut velocity) pairs of the sample at `sample_ns`; None: not checked."""
        k = round(sample_ns / self.period_ns)
        outer = k % self.outer_every == 0
        if not (outer or self.every_sample):
            return None
        ahead: Callable[[int], JointState] | None = None
        if self.model is not None:
            model, held = self.model, self.inner
            hold = (held.deflection_m, held.sliding) if held.deflection_m is not None else None

            def model_ahead(h_ns: int) -> JointState:
                return model.predict_held(fb, sample_ns, sample_ns + h_ns, hold)
            ahead = model_ahead
        js = JointState(fb[0], fb[1])
        t_ns, ds, reason = self.generator.on_sample(sample_ns, js, ahead)
        seq = k + 1
        self._stale(sample_ns)
        hold = self._fallback(sample_ns, js, ds)
        if reason is not None:
            self.generator.sent(seq, sample_ns)
            self.events += 1
            self.sampled_at[seq] = sample_ns
            self.sampled_at.pop(seq - 100_000, None)
        record = tracking_record(t_ns, seq, fb[0], ds, reason, 0) if outer and t_ns <= self.duration_ns else None
        return EdgeDecision(seq, reason, self.events, record, hold)

    def _fallback(self, sample_ns: int, js: JointState, ds: Any
                  ) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """The local (v_x, s) to hold at this sample while an answer is overdue (None: keep the held setpoint)."""
        overdue = self.fallback and self.generator.overdue(sample_ns)
        self.fallback_episodes += overdue and not self._in_fallback
        self._in_fallback = overdue
        if not overdue:
            return None
        params, c, rho, boundary_layer = self._smc
        vx, s = smc_deflection(js, ds, params, c, rho, boundary_layer)
        if not admissible(vx, self._envelope):
            self.fallback_rejected += 1
            return None
        self.fallback_samples += 1
        self._last_hold_ns = sample_ns
        return vx, s

    def _stale(self, sample_ns: int) -> None:
        """How long the edge has held a setpoint computed for a sample before the oldest state it still waits an answer
        to (with the zero-order hold: until an answer comes; with the local fallback: the answer timeout at most)."""
        gen = self.generator
        if not gen.outstanding or self._last_hold_ns is None or self._last_hold_ns >= gen.outstanding[0][1]:
            return
        stale = sample_ns - gen.outstanding[0][1]
        self.max_stale_ns = max(self.max_stale_ns, stale)
        self.max_stale_excess_ns = max(self.max_stale_excess_ns, stale - gen.answer_timeout_ns)

    def answered(self, state_seq: int, now_ns: int) -> None:
        sampled = self.sampled_at.get(state_seq, now_ns)
        self._last_hold_ns = sampled        # the held setpoint is the answer to the state of that sample
        self.generator.answered(state_seq, now_ns, sampled)

    def heard(self, state_seq: int, now_ns: int) -> None:
        """The controller answered `state_seq` but the edge refused the answer (the setpoint envelope)."""
        self.generator.heard(state_seq, now_ns)

    def drive_cleared(self, sample_ns: int) -> bool:
        """The edge has just cleared the drive's safe state (CLEAR_ERRORS sent). If that happened inside the current
        anchor's lead-in, the lead-in's clock ran while the drive could not follow (its first commands met the
        faulted drive: an edge restart, a controller restart after the watchdog), so the limb is behind a moving
        x_d and the SMC catches up at once; re-anchor at the next checked sample instead, from the state the drive
        is in when it runs again (both ends build the lead-in from that INITIAL state). True if it re-anchors."""
        g = self.generator
        if g.t0_ns is None or g.time_of(sample_ns) >= 0:
            return False        # not anchored yet, or in the measured cycles: t continues
        g.t0_ns = None          # `_needs_anchor`: anchor at the next checked sample
        self.resume_anchors += 1
        return True

    def stats(self) -> dict[str, int]:
        return {"edge_events": self.events, "edge_retriggers": self.generator.retriggers,
                "edge_reanchors": self.generator.reanchors, "edge_resume_anchors": self.resume_anchors}

    def fallback_stats(self) -> dict[str, int]:
        """The local fallback's counters and the longest stale hold (in the edge's /stats)."""
        return {"edge_fallback_samples": self.fallback_samples, "edge_fallback_episodes": self.fallback_episodes,
                "edge_fallback_rejected": self.fallback_rejected, "edge_max_stale_ms": self.max_stale_ns // 1_000_000}


def tracking_record(t_ns: int, seq: int, theta_rad: tuple[float, float], ds: Any, reason: Any,
                    setpoint_seq: int) -> dict[str, Any]:
    """The per-state tracking record (published as JSON on the `event` key; the offline engine builds the same);
    `reason` None: no event at this state."""
    return tracking_fields(t_ns, seq, theta_rad, ds.theta_rad, None if reason is None else reason.name, setpoint_seq)


def tracking_fields(t_ns: int, seq: int, theta_rad: tuple[float, float], theta_d_rad: tuple[float, float],
                    reason_name: str | None, setpoint_seq: int) -> dict[str, Any]:
    """`tracking_record` of the desired angles theta_d_rad and the event's reason name (None: no event)."""
    sent = reason_name is not None
    return {"t_s": t_ns * 1e-9, "state_seq": seq, "theta1_rad": theta_rad[0], "theta2_rad": theta_rad[1],
            "theta1_d_rad": theta_d_rad[0], "theta2_d_rad": theta_d_rad[1], "event": sent,
            "reason": reason_name if sent else "", "setpoint_seq": setpoint_seq if sent else 0}

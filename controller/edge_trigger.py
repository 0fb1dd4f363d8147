"""Sensor-side event generator (the trigger at the edge, issue 16): Eq. 16-19, the ||X~|| > r rule and the heartbeat
evaluated on the edge's own samples, so that a state crosses the uplink only on an event and the controller answers
each one with v_x(t_i) — both directions event-triggered.

Pure core (no clock, no I/O): `on_sample` takes a measured sample and says whether to publish it; `sent` and
`answered` tell it about the state in flight. The edge needs x_d(t): it builds the same trajectory as the controller
and the same lead-in from the first measured state (t = 0 is that sample + `lead_in_s`). While a published state has
no answer yet the trigger is not evaluated (no burst of duplicate events while the answer is in flight), until
`answer_timeout_ns` has passed — a lost state or a lost setpoint then lets the next event through (re-trigger). The
timeout follows the measured round trip: max(`min_timeout_ns`, 3 x the smoothed round trip), capped at
`max_timeout_ns` (the edge's `max_answer_age_s`: an answer later than that is dropped anyway). A time trigger (TT)
is not gated at all: a time-triggered sensor publishes every checked sample however many answers are in flight
(`periodic_reason`, issue 29), also while the anchor's answer is awaited.

The trajectory anchor: the edge's t (and the lead-in) count from an anchor, a state published with reason INITIAL;
the controller counts its t from the same state (controller/remote_core.py), so both ends evaluate x_d(t) at the
same t. Until the controller has answered the anchor nothing else is published (ET; TT goes on publishing); when
no answer to it comes within `anchor_timeout_ns` (a controller that was not listening yet, a lost state or answer)
the edge re-anchors on its current sample, and also when no answer at all came for `reanchor_after_ns` (a restarted
controller: the edge has stopped commanding by then); an answer the edge refused (the setpoint envelope) counts for
both (`heard`). Before this, the edge anchored on its own first sample whether
or not the controller received it, so a controller that started listening later ran the trajectory shifted by that
time (issue 16's real-time failure, docs/studies/et-over-links.md).

Overdue answers (the local fallback of a silent downlink, docs/deviations.md section 17): `outstanding` holds the
states published since the newest answer; `overdue(sample_ns)` says the oldest of them has waited `answer_timeout_ns`
(the same loss decision as the re-trigger) without any answer, i.e. the downlink (or uplink) is silent and the held
setpoint is stale. The edge (controller/edge_events.py) then computes v_x itself until an answer comes.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from sea_hil.controller.smc import JointState, tracking_errors
from sea_hil.controller.trajectory import CsvTrajectory, DesiredSample, GaitTrajectory, LeadIn, anchored_lead_in
from sea_hil.controller.trigger import EventTrigger, TimeTrigger, _distance, epsilon
from sea_hil.protocol.payloads import TriggerReason


@dataclass
class EdgeEventGenerator:
    trigger: EventTrigger | TimeTrigger
    trajectory: GaitTrajectory | CsvTrajectory
    lead_in_ns: int
    lead_in_max_velocity_rad_s: float = float("inf")   # the stretch of a far start (as the controller's)
    min_timeout_ns: int = 20_000_000
    max_timeout_ns: int = 0           # 0: no cap
    t0_ns: int | None = None
    lead_in: LeadIn | None = None
    awaiting_seq: int | None = None
    awaiting_since_ns: int = 0
    rtt_ns: float | None = None
    retriggers: int = 0
    lookahead: bool = True            # evaluate the trigger on the state extrapolated one round trip ahead
    anchor_timeout_ns: int = 250_000_000   # the anchor unanswered this long: re-anchor
    reanchor_after_ns: int = 500_000_000   # no answer at all this long after the anchor was answered: re-anchor
    anchor_seq: int | None = None     # the state seq of the anchor (None: not yet published)
    anchored: bool = False            # the controller has answered the anchor
    anchor_ns: int = 0                # sample time of the anchor
    last_answer_ns: int = 0
    reanchors: int = 0
    outstanding: list[tuple[int, int]] = field(default_factory=list)   # (seq, sample ns) of unanswered states
    _anchoring: bool = False          # the sample just checked is a new anchor (its seq comes with `sent`)
    _prev: tuple[int, tuple[float, float]] | None = None
    _alpha: tuple[float, float] = (0.0, 0.0)

    def desired(self, t_ns: int) -> DesiredSample:
        """x_d at the controller's time t (ns after the start of the measured cycles)."""
        if t_ns < 0 and self.lead_in is not None:
            return self.lead_in.sample(t_ns * 1e-9)
        return self.trajectory.sample(t_ns * 1e-9)

    def time_of(self, sample_ns: int) -> int:
        assert self.t0_ns is not None
        return sample_ns - self.t0_ns

    @property
    def answer_timeout_ns(self) -> int:
        timeout = self.min_timeout_ns if self.rtt_ns is None else max(self.min_timeout_ns, int(3.0 * self.rtt_ns))
        return min(timeout, self.max_timeout_ns) if self.max_timeout_ns else timeout

    def on_sample(self, sample_ns: int, js: JointState, ahead: Callable[[int], JointState] | None = None
                  ) -> tuple[int, DesiredSample, TriggerReason | None]:
        """(controller time t, x_d(t), the reason to publish this sample or None). `ahead(horizon_ns)`, if given,
        is the edge's model of the state `horizon_ns` ahead (used for the lookahead instead of extrapolation)."""
        anchor = self._needs_anchor(sample_ns)
        if anchor:
            self._anchor(sample_ns, js)
        t_ns = self.time_of(sample_ns)
        ds = self.desired(t_ns)
        if self.periodic:
            return t_ns, ds, self.periodic_reason(anchor)
        js_eval, t_eval, ds_eval = self._ahead(sample_ns, js, t_ns, ds, ahead)
        eps = epsilon(tracking_errors(js_eval, ds_eval), ds_eval.theta_rad, ds_eval.omega_rad_s)
        if anchor:
            self.trigger.update(t_eval, eps)
            return t_ns, ds, TriggerReason.INITIAL
        if not self.anchored:
            return t_ns, ds, None               # the anchor's answer is awaited: nothing else is published
        if self.awaiting_seq is not None:
            if sample_ns - self.awaiting_since_ns >= self.answer_timeout_ns:
                self.retriggers += 1            # the state or its answer was lost: let the next event through
                self.awaiting_seq = None
            elif not self.trigger_moved(eps):
                return t_ns, ds, None           # only the error moving again may fire while an answer is in flight
        reason = self.trigger.update(t_eval, eps)
        return t_ns, ds, reason

    @property
    def periodic(self) -> bool:
        """A time-triggered sensor (TT): it publishes every checked sample, answers in flight or not (issue 29)."""
        return isinstance(self.trigger, TimeTrigger)

    def periodic_reason(self, anchor: bool) -> TriggerReason:
        """The reason of a TT state: INITIAL at an anchor, else TIME, whether or not the anchor or any later state has
        been answered yet. Not gated on the answer in flight (the event trigger's burst guard below): that gate made
        TT stop-and-wait on a delayed link (issue 29: 488 of 1001 states at 5 ms +- 1 ms / 1 % each way). Answers
        are matched by state_seq (`answered`), a late one is dropped by the edge's intake as for ET; the anchor
        handshake is kept (re-anchor when the anchor's answer does not come within `anchor_timeout_ns`)."""
        return TriggerReason.INITIAL if anchor else TriggerReason.TIME

    def _needs_anchor(self, sample_ns: int) -> bool:
        if self.t0_ns is None:
            return True
        if self.anchored:
            silent = sample_ns - self.last_answer_ns >= self.reanchor_after_ns
        else:
            silent = sample_ns - self.anchor_ns >= self.anchor_timeout_ns
        self.reanchors += silent
        return silent

    def _anchor(self, sample_ns: int, js: JointState) -> None:
        """A new anchor at this sample: t = -lead_in here, the lead-in from this state, the trigger starts over."""
        lead_ns, self.lead_in = anchored_lead_in(js.theta_rad, js.omega_rad_s, self.trajectory.sample(0.0),
                                                 self.lead_in_ns, self.lead_in_max_velocity_rad_s)
        self.t0_ns, self.anchor_ns = sample_ns + lead_ns, sample_ns
        self.anchored, self._anchoring, self.awaiting_seq = False, True, None
        self.outstanding.clear()
        self.trigger.reset()

    def trigger_moved(self, eps: tuple[float, ...]) -> bool:
        """Would the event error rule (Eq. 19) fire for eps? (the r rule and the heartbeat would fire on every sample
        while an answer is in flight, so they wait for it)."""
        trig = self.trigger
        if not isinstance(trig, EventTrigger) or trig._eps_i is None:
            return False
        return _distance(trig._eps_i, eps) >= trig.threshold

    def _ahead(self, sample_ns: int, js: JointState, t_ns: int, ds: DesiredSample,
               model: Callable[[int], JointState] | None) -> tuple[JointState, int, DesiredSample]:
        """The state one smoothed round trip ahead (when the answer to an event now would act), extrapolated with the
        measured velocity and a smoothed acceleration (finite differences of the 1 kHz or outer samples)."""
        prev = self._prev
        if prev is not None and sample_ns > prev[0]:
            dt = (sample_ns - prev[0]) * 1e-9
            (w1, w2), (p1, p2), (al1, al2) = js.omega_rad_s, prev[1], self._alpha
            self._alpha = (0.8 * al1 + 0.2 * ((w1 - p1) / dt), 0.8 * al2 + 0.2 * ((w2 - p2) / dt))
        self._prev = (sample_ns, js.omega_rad_s)
        if not self.lookahead or not self.rtt_ns:
            return js, t_ns, ds
        t_eval = t_ns + int(self.rtt_ns)
        if model is not None:
            return model(int(self.rtt_ns)), t_eval, self.desired(t_eval)
        h = self.rtt_ns * 1e-9
        (q1, q2), (w1, w2), (a1, a2) = js.theta_rad, js.omega_rad_s, self._alpha
        th = (q1 + w1 * h + 0.5 * a1 * h * h, q2 + w2 * h + 0.5 * a2 * h * h)
        om = (w1 + a1 * h, w2 + a2 * h)
        return JointState(th, om), t_eval, self.desired(t_eval)

    def overdue(self, sample_ns: int) -> bool:
        """The oldest state published since the newest answer has waited at least the answer timeout (anchored
        only: before the controller has answered the anchor there is no agreed t to control on)."""
        return self.anchored and bool(self.outstanding) \
            and sample_ns - self.outstanding[0][1] >= self.answer_timeout_ns

    def sent(self, seq: int, sample_ns: int) -> None:
        self.awaiting_seq, self.awaiting_since_ns = seq, sample_ns
        self.outstanding.append((seq, sample_ns))
        if len(self.outstanding) > 64:      # a long outage: the setpoint timeout has stopped the edge by then
            del self.outstanding[0]
        if self._anchoring:
            self.anchor_seq, self._anchoring = seq, False

    def heard(self, state_seq: int, now_ns: int) -> None:
        """An answer to state `state_seq` arrived at `now_ns` and the edge refused it (outside the setpoint envelope):
        the controller is listening and has anchored where the edge did, so the anchor handshake and the silence
        rule (`reanchor_after_ns`) count it. Without this a drive that cannot follow (latched in a fault that needs
        the user) made every answer of the lead-in too large, the edge re-anchored each `reanchor_after_ns` and the
        cycles never began (a lockstep session ran on past its end). The in-flight gate, the round trip and the
        outstanding states (the local fallback) do not count it: nothing was applied."""
        self.last_answer_ns = max(self.last_answer_ns, now_ns)
        if not self.anchored and state_seq == self.anchor_seq:
            self.anchored = True

    def answered(self, state_seq: int, now_ns: int, sampled_ns: int) -> None:
        """A setpoint answering state `state_seq` (sampled at `sampled_ns`) was applied at `now_ns`."""
        rtt = float(now_ns - sampled_ns)
        self.rtt_ns = rtt if self.rtt_ns is None else 0.875 * self.rtt_ns + 0.125 * rtt
        self.last_answer_ns = now_ns
        if not self.anchored and state_seq == self.anchor_seq:
            self.anchored = True
        if self.awaiting_seq is not None and state_seq >= self.awaiting_seq:
            self.awaiting_seq = None
        while self.outstanding and self.outstanding[0][0] <= state_seq:
            del self.outstanding[0]

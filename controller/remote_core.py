"""The remote controller's pure core (issue 12): one accepted state in, the messages to send out. No clock read of
its own, no I/O: the node (controller/remote.py) decodes, checks sequence and trajectory, passes the state with
its arrival time (`arrival(p)`, on the edge's sample clock, see `sea_hil.runtime`) and the wall clock to stamp
messages with, and publishes what `on_state` returns.

Per state: the controller's time t (t = 0: start of the measured cycles; the `LeadIn` before it; with the trigger at
the edge counted from the edge's anchor, its latest INITIAL state, controller/edge_trigger.py), the outer SMC and
trigger (`OuterController`; with the trigger at the edge every event state is answered), with `compensation =
"predict"` for the state predicted at the instant the setpoint will act (controller/predictor.py), and with
`inner = "remote"` the backstepping voltage every state.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property, partial
from typing import Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_events import tracking_record
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.outer import OuterController, Setpoint
from sea_hil.controller.predictor import Predictor
from sea_hil.controller.smc import JointState, smc_deflection
from sea_hil.controller.trajectory import LeadIn, anchored_lead_in, make_trajectory, trajectory_id
from sea_hil.protocol.payload_hot import encode_setpoint
from sea_hil.protocol.payloads import StatePayload, TriggerReason, VoltagePayload, encode


@dataclass(frozen=True)
class Answer:
    messages: list[tuple[str, bytes]]     # ("setpoint" | "voltage", encoded payload), in order
    setpoint: Setpoint | None
    make_record: Callable[[], dict[str, Any]] | None = None   # see `record`

    @cached_property
    def record(self) -> dict[str, Any] | None:
        """The tracking record (the node publishes it as JSON), None with the trigger at the edge. Made when first
        read, so a node sends the setpoint first: the desired motion of the record is not on the answer's path."""
        return None if self.make_record is None else self.make_record()


class ControllerCore:
    def __init__(self, cfg: SeaHilConfig, mode: str, inner: str = "edge", cycles: int = 1, epoch: int = 0) -> None:
        self.cfg, self.inner_mode = cfg, inner
        self.epoch = epoch                  # the controller's session epoch, in every payload it makes
        self.params = nominal_params(cfg)
        self.traj = make_trajectory(cfg.trajectory)
        self.outer = OuterController(cfg, self.params, mode)
        self.inner = InnerLoop(cfg, self.params, cfg.plant.initial_theta_rad, cfg.controller.sample_period_s)
        self.edge_trigger = cfg.trigger.placement == "edge"      # answer every EVENT_STATE
        self.trajectory_id = trajectory_id(cfg.trajectory)
        self.predictor: Predictor | None = None
        if cfg.controller.compensation == "predict":            # the edge's closed loop at its own rate
            period_s = 1.0 / cfg.can.feedback_rate_hz
            edge_inner = InnerLoop(cfg, self.params, cfg.plant.initial_theta_rad, period_s)
            self.predictor = Predictor.for_inner(edge_inner, int(round(period_s * 1e9)), cfg.sim.substeps)
            self.predictor.warm(cfg.plant.initial_theta_rad)
        self.duration_ns = int(round(self.traj.period_s * cycles * 1e9))
        self.lead_in_ns = int(round(cfg.trajectory.lead_in_s * 1e9))
        self.lead_in: LeadIn | None = None
        self.t0_ns: int | None = None
        self.last_t_ns = 0
        self.setpoint_seq = 0
        self.states = 0
        self.unanchored = 0                 # edge trigger: states before any anchor (its INITIAL state was lost)
        self.done = False

    def restart_at(self, p: StatePayload) -> None:
        """A new state stream (edge restart): the trajectory continues where it stopped."""
        self.t0_ns = p.sample_t_ns - self.last_t_ns

    def on_state(self, p: StatePayload, arrival: Callable[[StatePayload], int], wall_ns: Callable[[], int]
                 ) -> Answer | None:
        """The answer to one new state; None once past the cycles (`done`). Raises ArithmeticError / ValueError /
        MalformedPayload for a state it cannot use (the node counts it)."""
        if self.edge_trigger:       # the edge's anchor (an INITIAL state) sets t; nothing to answer before one
            if p.reason is TriggerReason.INITIAL:   # type: ignore[attr-defined]
                self._anchor(p)
            elif self.t0_ns is None:
                self.unanchored += 1
                return Answer([], None, None)
        elif self.t0_ns is None:    # the paper's placement: t counts from the first state handled
            self._anchor(p)
        t0_ns = self.t0_ns
        assert t0_ns is not None   # anchored above
        t_ns = p.sample_t_ns - t0_ns
        self.last_t_ns = t_ns
        if t_ns > self.duration_ns:
            self.done = True
            return None
        sp, now = self._decide(p, t_ns, arrival)
        messages: list[tuple[str, bytes]] = []
        if sp is not None:
            self.setpoint_seq += 1
            self.inner.hold(sp.deflection_m, sp.sliding)
            if self.predictor is not None:
                self.predictor.sent(self.predictor.apply_time_ns(now), sp.deflection_m, sp.sliding)
            if self.inner_mode == "edge":
                messages.append(("setpoint", encode_setpoint(self.setpoint_seq, wall_ns(), p.seq, sp.deflection_m,
                                                             sp.sliding, sp.reason, epoch=self.epoch)))
        if self.inner_mode == "remote":
            m = (*p.theta_rad, *p.omega_rad_s, *p.delta_m, *p.nut_vel_m_s)
            u = self.inner.voltage(m)
            self.setpoint_seq += 1
            messages.append(("voltage", encode(VoltagePayload(self.setpoint_seq, wall_ns(), p.seq, u,
                                                              epoch=self.epoch))))
        self.states += 1
        if self.edge_trigger:          # with the trigger at the edge, the edge records every outer sample
            return Answer(messages, sp)
        return Answer(messages, sp, partial(self._record, t_ns, p.seq, p.theta_rad, sp.reason if sp else None,
                                            self.setpoint_seq if messages else 0))

    def _record(self, t_ns: int, seq: int, theta_rad: tuple[float, float], reason: Any, setpoint_seq: int
                ) -> dict[str, Any]:
        return tracking_record(t_ns, seq, theta_rad, self.desired(t_ns), reason, setpoint_seq)

    def _anchor(self, p: StatePayload) -> None:
        """t = -lead_in at state p, the lead-in from its measured state; stretched when the limb is far from the
        trajectory's start (a restart after a safe-state stop: `trajectory.lead_in_max_velocity_rad_s`, issue 19)."""
        tc = self.cfg.trajectory
        lead_ns, self.lead_in = anchored_lead_in(p.theta_rad, p.omega_rad_s, self.traj.sample(0.0), self.lead_in_ns,
                                                 tc.lead_in_max_velocity_rad_s)
        self.t0_ns = p.sample_t_ns + lead_ns

    def desired(self, t_ns: int) -> Any:
        return self.lead_in.sample(t_ns * 1e-9) if t_ns < 0 and self.lead_in else self.traj.sample(t_ns * 1e-9)

    def _decide(self, p: StatePayload, t_ns: int, arrival: Callable[[StatePayload], int]
                ) -> tuple[Setpoint | None, int]:
        """The setpoint for state p (None: no event) and the arrival time used; with `predict` for the state
        predicted at the instant the setpoint will act, as the offline engine does."""
        js, t_eval, now = JointState(p.theta_rad, p.omega_rad_s), t_ns, 0
        if self.predictor is not None:
            now = arrival(p)
            self.predictor.observe_uplink(now - p.sample_t_ns)
            apply_ns = self.predictor.apply_time_ns(now)
            js = self.predictor.predict((p.theta_rad, p.omega_rad_s, p.delta_m, p.nut_vel_m_s), p.sample_t_ns,
                                        apply_ns)
            t_eval = t_ns + (apply_ns - p.sample_t_ns)   # = apply_ns - t0_ns
        ds_eval = self.desired(t_eval)
        if not self.edge_trigger:
            return self.outer.step(t_eval, p.seq, js, ds_eval), now
        cc = self.cfg.controller
        vx, s = smc_deflection(js, ds_eval, self.params, cc.c, cc.rho, cc.boundary_layer)
        return Setpoint(vx, s, p.reason, p.seq, t_eval), now  # type: ignore[attr-defined]

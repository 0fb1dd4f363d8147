"""Outer loop of the remote controller: samples the joint state every sample period, evaluates the trigger and,
on an event, computes v_x(t_i) (Eq. 17) to transmit. Time-triggered (tt) mode transmits every sample."""
from __future__ import annotations

from dataclasses import dataclass

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.smc import JointState, smc_deflection, tracking_errors
from sea_hil.controller.trajectory import DesiredSample
from sea_hil.controller.trigger import EventTrigger, TimeTrigger, epsilon, error_threshold
from sea_hil.mechanics import LimbParams
from sea_hil.protocol.payloads import TriggerReason


@dataclass(frozen=True, slots=True)
class Setpoint:
    """What crosses the downlink on an event: v_x(t_i), the sliding variable s(t_i) used by the inner loop's
    Eq. 27 cross term, why it was sent, and which state sample it was computed from."""
    deflection_m: tuple[float, float]
    sliding: tuple[float, float]
    reason: TriggerReason
    state_seq: int
    t_ns: int


class OuterController:
    def __init__(self, cfg: SeaHilConfig, params: LimbParams, mode: str) -> None:
        if mode not in ("tt", "et"):
            raise ValueError(f"controller mode must be 'tt' or 'et', not {mode!r}")
        cc, tc = cfg.controller, cfg.trigger
        self.mode = mode
        self._p = params
        self._c, self._rho, self._bl = cc.c, cc.rho, cc.boundary_layer
        self._trigger: EventTrigger | TimeTrigger
        if mode == "et":
            self._trigger = EventTrigger(error_threshold(tc.eta, tc.lipschitz_l, cc.c), tc.r,
                                         int(round(tc.max_inter_event_s * 1e9)))
        else:
            self._trigger = TimeTrigger()

    def step(self, t_ns: int, state_seq: int, js: JointState, ds: DesiredSample) -> Setpoint | None:
        """One outer sample; returns the setpoint to transmit, or None when no event fires."""
        xt = tracking_errors(js, ds)
        reason = self._trigger.update(t_ns, epsilon(xt, ds.theta_rad, ds.omega_rad_s))
        if reason is None:
            return None
        vx, s = smc_deflection(js, ds, self._p, self._c, self._rho, self._bl)
        return Setpoint(vx, s, reason, state_seq, t_ns)

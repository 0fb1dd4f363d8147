"""Inner loop (runs on the edge, next to the CAN bus): holds the latest setpoint and turns each 1 kHz
measurement into saturated SEA voltages with the backstepping law."""
from __future__ import annotations

import logging

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.backstepping import (
    COMPENSATION,
    NO_ESTIMATE,
    InnerGains,
    Measurement,
    backstepping_voltage,
    cross_term_weight,
)
from sea_hil.controller.observer import OBSERVER_UNSTARTED, Estimate, ObserverState, observer_step
from sea_hil.mechanics import LimbParams

log = logging.getLogger(__name__)


def _sat(v: float, lim: float) -> float:
    return lim if v > lim else (-lim if v < -lim else v)


def limited_voltage(m: Measurement, vx: tuple[float, float], s: tuple[float, float], p: LimbParams,
                    gains: InnerGains, limit_v: float,
                    d_hat: Estimate = NO_ESTIMATE) -> tuple[float, float, bool]:
    """(u1, u2, saturated): backstepping voltages clipped to +-limit_v; a NaN (degenerate state) commands nothing.

    Plain float code: the offline simulation also compiles it with numba (sea_hil/offline/closed_loop.py)."""
    u1, u2 = backstepping_voltage(m, vx, s, p, gains, d_hat)
    if u1 != u1 or u2 != u2:
        return 0.0, 0.0, False
    s1, s2 = _sat(u1, limit_v), _sat(u2, limit_v)
    return s1, s2, (s1 != u1 or s2 != u2)


def inner_step(m: Measurement, vx: tuple[float, float], s: tuple[float, float], hold_measured: bool,
               obs: ObserverState, p: LimbParams, gains: InnerGains, limit_v: float, dt_s: float
               ) -> tuple[float, float, bool, ObserverState]:
    """One inner-loop step as the edge runs it: observer update (if compensating), then the limited voltage.
    hold_measured (no setpoint yet): hold the measured deflection, no compensating deflection either.
    Returns (u1, u2, saturated, new observer state). Plain float code (compiled offline with numba)."""
    v = (m[4], m[5]) if hold_measured else vx
    if gains.compensation == 0:
        u1, u2, saturated = limited_voltage(m, v, s, p, gains, limit_v, NO_ESTIMATE)
        return u1, u2, saturated, obs
    obs, d_hat = observer_step(m, obs, p, gains.observer_rad_s, dt_s)
    if hold_measured:
        d_hat = NO_ESTIMATE
    u1, u2, saturated = limited_voltage(m, v, s, p, gains, limit_v, d_hat)
    return u1, u2, saturated, obs


MAX_OBSERVER_POLE_STEP = 0.4
"""Largest observer pole x period: the forward-Euler observer is well damped only for w0 dt well below 1."""


def observer_bandwidth(bandwidth_rad_s: float, period_s: float) -> float:
    """The configured observer pole, capped at MAX_OBSERVER_POLE_STEP / period_s (e.g. the 10 ms remote placement)."""
    cap = MAX_OBSERVER_POLE_STEP / period_s
    if bandwidth_rad_s > cap:
        log.info("observer bandwidth %.0f rad/s capped at %.0f rad/s for a %.4f s inner period",
                    bandwidth_rad_s, cap, period_s)
        return cap
    return bandwidth_rad_s


class InnerLoop:
    """`params` is the controller's nominal model (controller/nominal.py); `period_s` the time between two calls
    of `voltage` (default: 1 / can.feedback_rate_hz), used by the disturbance observer."""

    def __init__(self, cfg: SeaHilConfig, params: LimbParams, theta0_rad: tuple[float, float],
                 period_s: float | None = None) -> None:
        cc = cfg.controller
        w = cross_term_weight(cc.cross_term_scale, params, cc.cross_term_bandwidth_rad_s, theta0_rad)
        self.period_s = period_s if period_s is not None else 1.0 / cfg.can.feedback_rate_hz
        self.gains = InnerGains(cc.kp1, cc.kp2, w, COMPENSATION[cc.disturbance_compensation],
                                observer_bandwidth(cc.observer_bandwidth_rad_s, self.period_s))
        self._p = params
        self._limit = params.voltage_limit
        self.deflection_m: tuple[float, float] | None = None
        self.sliding: tuple[float, float] = (0.0, 0.0)
        self.observer: ObserverState = OBSERVER_UNSTARTED
        self.saturated_steps = 0
        self.ramp_steps = max(0, int(round(cfg.safety.setpoint.resume_ramp_s / self.period_s)))
        self._ramp_from: tuple[float, float] = (0.0, 0.0)
        self._ramp_step = self.ramp_steps      # == ramp_steps: no ramp in progress

    def resume(self, deflection_m: tuple[float, float]) -> None:
        """Bumpless restart of the loop after the drive's safe state (docs/reliability.md, "Bumpless resume"): the
        observer starts again from the next measurement (its momentum estimate and lumped torque are stale after a
        stop; with d_hat = 0, like at the first sample) and the deflection command ramps linearly from the measured
        `deflection_m` to the held setpoint over `safety.setpoint.resume_ramp_s`, instead of a step. No-op with
        `resume_ramp_s = 0` (the step and the stale observer of before)."""
        if self.ramp_steps:
            self.observer = OBSERVER_UNSTARTED
            self._ramp_from, self._ramp_step = deflection_m, 0

    def hold(self, deflection_m: tuple[float, float], sliding: tuple[float, float]) -> None:
        self.deflection_m = deflection_m
        self.sliding = sliding

    def voltage(self, m: Measurement) -> tuple[float, float]:
        """Saturated voltages; before the first setpoint, hold the measured deflection (no motion commanded)."""
        held = self.deflection_m
        if held is not None and self._ramp_step < self.ramp_steps:
            self._ramp_step += 1
            f, (a1, a2) = self._ramp_step / self.ramp_steps, self._ramp_from
            held = (a1 + f * (held[0] - a1), a2 + f * (held[1] - a2))
        s1, s2, saturated, self.observer = inner_step(m, held or (0.0, 0.0), self.sliding, held is None,
                                                      self.observer, self._p, self.gains, self._limit, self.period_s)
        if saturated:
            self.saturated_steps += 1
        return s1, s2

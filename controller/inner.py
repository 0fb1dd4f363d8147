"""Inner loop (runs on the edge, next to the CAN bus): holds the latest setpoint and turns each 1 kHz
measurement into saturated SEA voltages with the backstepping law."""
from __future__ import annotations

from sea_hil.controller.backstepping import InnerGains, Measurement, backstepping_voltage, cross_term_weight
from sea_hil.config import SeaHilConfig
from sea_hil.mechanics import LimbParams


def _sat(v: float, lim: float) -> float:
    return lim if v > lim else (-lim if v < -lim else v)


def limited_voltage(m: Measurement, vx: tuple[float, float], s: tuple[float, float], p: LimbParams,
                    gains: InnerGains, limit_v: float) -> tuple[float, float, bool]:
    """(u1, u2, saturated): backstepping voltages clipped to +-limit_v; a NaN (degenerate state) commands nothing.

    Plain float code: the offline simulation also compiles it with numba (sea_hil/offline/closed_loop.py)."""
    u1, u2 = backstepping_voltage(m, vx, s, p, gains)
    if u1 != u1 or u2 != u2:
        return 0.0, 0.0, False
    s1, s2 = _sat(u1, limit_v), _sat(u2, limit_v)
    return s1, s2, (s1 != u1 or s2 != u2)


class InnerLoop:
    def __init__(self, cfg: SeaHilConfig, params: LimbParams, theta0_rad: tuple[float, float]) -> None:
        cc = cfg.controller
        w = cross_term_weight(cc.cross_term_scale, params, cc.cross_term_bandwidth_rad_s, theta0_rad)
        self.gains = InnerGains(cc.kp1, cc.kp2, w)
        self._p = params
        self._limit = params.voltage_limit
        self.deflection_m: tuple[float, float] | None = None
        self.sliding: tuple[float, float] = (0.0, 0.0)
        self.saturated_steps = 0

    def hold(self, deflection_m: tuple[float, float], sliding: tuple[float, float]) -> None:
        self.deflection_m = deflection_m
        self.sliding = sliding

    def voltage(self, m: Measurement) -> tuple[float, float]:
        """Saturated voltages; before the first setpoint, hold the measured deflection (no motion commanded)."""
        vx = self.deflection_m if self.deflection_m is not None else (m[4], m[5])
        s1, s2, saturated = limited_voltage(m, vx, self.sliding, self._p, self.gains, self._limit)
        if saturated:
            self.saturated_steps += 1
        return s1, s2

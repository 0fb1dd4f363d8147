"""Inner loop (runs on the edge, next to the CAN bus): holds the latest setpoint and turns each 1 kHz
measurement into saturated SEA voltages with the backstepping law."""
from __future__ import annotations

from controller.backstepping import InnerGains, Measurement, backstepping_voltage, cross_term_weight
from protocol.config import SeaHilConfig
from protocol.mechanics import LimbParams


def _sat(v: float, lim: float) -> float:
    return lim if v > lim else (-lim if v < -lim else v)


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
        u1, u2 = backstepping_voltage(m, vx, self.sliding, self._p, self.gains)
        if u1 != u1 or u2 != u2:  # NaN from a degenerate state: command nothing
            return 0.0, 0.0
        s1, s2 = _sat(u1, self._limit), _sat(u2, self._limit)
        if s1 != u1 or s2 != u2:
            self.saturated_steps += 1
        return s1, s2

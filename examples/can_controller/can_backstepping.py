"""Backstepping inner loop (paper Eq. 24-31) from the held deflection setpoint v_x(t_i) to the SEA voltages, written
without sea-hil: z1 = measured deflection, z2 = a(theta) omega - nut velocity, v_x held between events (its
derivative zero), the Eq. 27 cross term -(g_x)^T s weighted by w (`[controller] cross_term_scale`: "paper" w = 1,
"off" w = 0, "normalized" w = omega_c^2 / ||g_x(theta0)||_F^2 -- docs/deviations.md), voltages clipped to the
driver's limit. The model (`Limb`) is the nominal one of ../external_controller/etsmc.py.
"""
from __future__ import annotations

from typing import Any

from etsmc import Limb, Pair

FD_STEP_S = 1e-4    # finite-difference horizon for d g_x / dt along the joint velocity


def cross_term_weight(cc: dict[str, Any], limb: Limb, theta0: Pair) -> float:
    mode = cc["cross_term_scale"]
    if mode == "paper":
        return 1.0
    if mode == "off":
        return 0.0
    a1, a2, _, _ = limb.geometry(*theta0)
    _, _, g = limb.fx_gx(theta0[0], theta0[1], 0.0, 0.0, a1, a2)
    bw = cc["cross_term_bandwidth_rad_s"]
    return bw * bw / sum(v * v for v in g)


def _cross(g: tuple[float, ...], s: Pair) -> Pair:
    return g[0] * s[0] + g[2] * s[1], g[1] * s[0] + g[3] * s[1]


def _sat(v: float, lim: float) -> float:
    return lim if v > lim else (-lim if v < -lim else v)


class InnerLoop:
    def __init__(self, cfg: dict[str, Any], limb: Limb) -> None:
        cc = cfg["controller"]
        self.limb, self.kp1, self.kp2 = limb, cc["kp1"], cc["kp2"]
        self.w = cross_term_weight(cc, limb, tuple(cfg["plant"]["initial_theta_rad"]))
        self.deflection_m: Pair | None = None
        self.sliding: Pair = (0.0, 0.0)

    def hold(self, deflection_m: Pair, sliding: Pair) -> None:
        self.deflection_m, self.sliding = deflection_m, sliding

    def _g_dot(self, q1: float, q2: float, w1: float, w2: float) -> tuple[float, ...]:
        h, lb = FD_STEP_S, self.limb
        a1, a2, _, _ = lb.geometry(q1 + w1 * h, q2 + w2 * h)
        _, _, gp = lb.fx_gx(q1 + w1 * h, q2 + w2 * h, 0.0, 0.0, a1, a2)
        a1, a2, _, _ = lb.geometry(q1 - w1 * h, q2 - w2 * h)
        _, _, gm = lb.fx_gx(q1 - w1 * h, q2 - w2 * h, 0.0, 0.0, a1, a2)
        return tuple((p - m) / (2.0 * h) for p, m in zip(gp, gm, strict=True))

    def voltage(self, m: tuple[float, ...]) -> Pair:
        """Saturated voltages for measurement (theta1, theta2, omega1, omega2, delta1, delta2, nut_vel1, nut_vel2);
        before the first setpoint the measured deflection is held (no motion commanded); NaN commands 0 V."""
        q1, q2, w1, w2, z11, z12, rd1, rd2 = m
        vx = self.deflection_m if self.deflection_m is not None else (z11, z12)
        lb, s = self.limb, self.sliding
        a1, a2, a1p, a2p = lb.geometry(q1, q2)
        f1, f2, g = lb.fx_gx(q1, q2, w1, w2, a1, a2)
        z21, z22 = a1 * w1 - rd1, a2 * w2 - rd2
        e11, e12 = vx[0] - z11, vx[1] - z12
        acc1, acc2 = f1 + g[0] * z11 + g[1] * z12, f2 + g[2] * z11 + g[3] * z12
        fr1, fr2 = a1 * acc1 + a1p * w1 * w1, a2 * acc2 + a2p * w2 * w2
        if self.w != 0.0:
            c1, c2 = _cross(g, s)
            cd1, cd2 = _cross(self._g_dot(q1, q2, w1, w2), s)
            c1, c2, cd1, cd2 = self.w * c1, self.w * c2, self.w * cd1, self.w * cd2
        else:
            c1 = c2 = cd1 = cd2 = 0.0
        v11, v12 = self.kp1 * e11 - c1, self.kp1 * e12 - c2           # Eq. 27, vdot_x = 0
        v1d1, v1d2 = -self.kp1 * z21 - cd1, -self.kp1 * z22 - cd2
        cn = lb.nut_damping
        u1 = fr1 + cn * rd1 - self.kp2 * (v11 - z21) - v1d1 - e11      # Eq. 31
        u2 = fr2 + cn * rd2 - self.kp2 * (v12 - z22) - v1d2 - e12
        if u1 != u1 or u2 != u2:
            return 0.0, 0.0
        return _sat(u1, lb.voltage_limit), _sat(u2, lb.voltage_limit)

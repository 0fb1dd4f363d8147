"""ET-SMC outer loop written from the paper and docs/external-controller.md alone (no sea-hil import): the nominal
limb model (Eq. 1-2, 8), the gait and the lead-in, the sliding-mode law (Eq. 12-13) and the event trigger (Eq. 16-19,
the ||X~|| > r rule, a heartbeat). Plain floats in the same order of operations as sea-hil's built-in controller, so
a lockstep session with this controller reproduces the built-in one's decisions.

Parameters come from the session's config TOML (`[plant]`, `[controller]`, `[trigger]`, `[trajectory]`).
"""
from __future__ import annotations

import math
from typing import Any, NamedTuple

Pair = tuple[float, float]

# Gait of docs/external-controller.md: offset + sum of amplitude * sin(k w t + phase), w = 2 pi / period_s
HIP = (0.05, ((0.35, 1, 0.0), (0.05, 2, 0.0)))
KNEE = (0.55, ((0.40, 1, -0.5 * math.pi - 0.5), (0.10, 2, 1.0)))


class Limb:
    """Nominal model of the 2-DOF limb from `[plant]`: SEA moment arms, mass matrix, N terms, f_x and g_x."""

    def __init__(self, plant: dict[str, Any]) -> None:
        d = [float(v) for v in plant["d_m"]]
        self.d3, self.d4, self.d8, self.d9 = d[2], d[3], d[7], d[8]
        self.sigma1, self.sigma2 = math.atan2(d[1], d[0]), math.atan2(d[6], d[5])
        self.alpha1, self.alpha2 = plant["alpha1_rad"], plant["alpha2_rad"]
        m1, m2, r1, r2, l1 = plant["m1_kg"], plant["m2_kg"], plant["r1_m"], plant["r2_m"], plant["l1_m"]
        i1, i2, g = plant["i1_kgm2"], plant["i2_kgm2"], plant["g_m_s2"]
        i2_c = i2 if plant["include_i2_in_coupling"] else 0.0
        m2r2sq = m2 * r2 ** 2
        self.m11_const = m1 * r1 ** 2 + i1 + m2 * l1 ** 2 + m2r2sq + i2_c
        self.m12_const = m2r2sq + i2_c
        self.m22 = m2r2sq + i2
        self.b_coupling = m2 * l1 * r2
        self.grav1 = (m1 * r1 + m2 * l1) * g
        self.grav2 = m2 * r2 * g
        self.b1, self.b2 = plant["b1_nms"], plant["b2_nms"]
        self.k1, self.k2 = plant["k1_n_per_m"], plant["k2_n_per_m"]
        self.nut_damping, self.voltage_limit = plant["nut_damping_per_s"], plant["voltage_limit_v"]

    def geometry(self, q1: float, q2: float) -> tuple[float, float, float, float]:
        """(a1, a2, a1', a2'): moment arms a_i = dL_Si / dtheta_i of the cosine-rule SEA lengths (Eq. 1) and their
        derivatives d2L_Si / dtheta_i2."""
        b1 = 0.5 * math.pi - self.sigma1 + q1 - self.alpha1
        b2 = math.pi - self.sigma2 + q2 - self.alpha2
        c1, s1, c2, s2 = math.cos(b1), math.sin(b1), math.cos(b2), math.sin(b2)
        k1, k2 = self.d3 * self.d4, self.d8 * self.d9
        len1 = math.sqrt(self.d3 * self.d3 + self.d4 * self.d4 - 2.0 * k1 * c1)
        len2 = math.sqrt(self.d8 * self.d8 + self.d9 * self.d9 - 2.0 * k2 * c2)
        a1, a2 = k1 * s1 / len1, k2 * s2 / len2
        return a1, a2, (k1 * c1 - a1 * a1) / len1, (k2 * c2 - a2 * a2) / len2

    def fx_gx(self, q1: float, q2: float, w1: float, w2: float, a1: float, a2: float
              ) -> tuple[float, float, tuple[float, float, float, float]]:
        """f_x = M^-1 N and g_x = M^-1 diag(-k1 a1, -k2 a2) (Eq. 8), g_x row-major."""
        m11, m12, m22 = self.mass_matrix(q2)
        n1, n2 = self.n_terms(q1, q2, w1, w2)
        det = m11 * m22 - m12 * m12
        f1, f2 = (m22 * n1 + m12 * n2) / det, (m12 * n1 + m11 * n2) / det
        e1, e2 = -self.k1 * a1, -self.k2 * a2
        return f1, f2, (m22 * e1 / det, m12 * e2 / det, m12 * e1 / det, m11 * e2 / det)

    def mass_matrix(self, q2: float) -> tuple[float, float, float]:
        """(M11, M12, M22), M = [[M11, -M12], [-M12, M22]] (Eq. 2)."""
        bc = self.b_coupling * math.cos(q2)
        return self.m11_const + 2.0 * bc, self.m12_const + bc, self.m22

    def n_terms(self, q1: float, q2: float, w1: float, w2: float) -> Pair:
        bs = self.b_coupling * math.sin(q2)
        sg = math.sin(q2 - q1)
        n1 = -self.grav1 * math.sin(q1) + self.grav2 * sg - bs * (w2 * w2 - 2.0 * w1 * w2) - self.b1 * w1
        n2 = -self.grav2 * sg - bs * w1 * w1 - self.b2 * w2
        return n1, n2


def switching(s: float, boundary_layer: float) -> float:
    if boundary_layer <= 0.0:
        return 1.0 if s > 0.0 else (-1.0 if s < 0.0 else 0.0)
    v = s / boundary_layer
    return 1.0 if v > 1.0 else (-1.0 if v < -1.0 else v)


def smc(limb: Limb, theta: Pair, omega: Pair, des: tuple[Pair, Pair, Pair], c: float, rho: float, bl: float
        ) -> tuple[Pair, Pair]:
    """Eq. 12-13 on the nominal model: (v_x, s), v_x = diag(-k a)^-1 (M y - N), y = xdd_d - c x~2 - rho sat(s)."""
    (qd1, qd2), (wd1, wd2), (ad1, ad2) = des
    (q1, q2), (w1, w2) = theta, omega
    x1, x2, x3, x4 = q1 - qd1, q2 - qd2, w1 - wd1, w2 - wd2
    s = (c * x1 + x3, c * x2 + x4)
    y1 = ad1 - c * x3 - rho * switching(s[0], bl)
    y2 = ad2 - c * x4 - rho * switching(s[1], bl)
    m11, m12, m22 = limb.mass_matrix(q2)
    n1, n2 = limb.n_terms(q1, q2, w1, w2)
    a1, a2, _, _ = limb.geometry(q1, q2)
    return ((m11 * y1 - m12 * y2 - n1) / (-limb.k1 * a1), (-m12 * y1 + m22 * y2 - n2) / (-limb.k2 * a2)), s


class Gait:
    def __init__(self, period_s: float) -> None:
        self._w = 2.0 * math.pi / period_s

    def _joint(self, spec: tuple, t: float) -> tuple[float, float, float]:
        q, qd, qdd = spec[0], 0.0, 0.0
        for amp, k, phase in spec[1]:
            wk = k * self._w
            s, c = math.sin(wk * t + phase), math.cos(wk * t + phase)
            q += amp * s
            qd += amp * wk * c
            qdd -= amp * wk * wk * s
        return q, qd, qdd

    def sample(self, t_s: float) -> tuple[Pair, Pair, Pair]:
        h, k = self._joint(HIP, t_s), self._joint(KNEE, t_s)
        return (h[0], k[0]), (h[1], k[1]), (h[2], k[2])


class LeadIn:
    """Quintic from the first measured (theta, omega, zero acceleration) onto the gait's t = 0, over t in [-T, 0)."""

    def __init__(self, theta: Pair, omega: Pair, target: tuple[Pair, Pair, Pair], duration_s: float) -> None:
        self.T = T = duration_s
        self.coef = []
        for j in (0, 1):
            q0, v0, a0 = theta[j], omega[j], 0.0
            q1, v1, a1 = target[0][j], target[1][j], target[2][j]
            h = q1 - q0 - v0 * T - 0.5 * a0 * T * T
            dv = v1 - v0 - a0 * T
            da = a1 - a0
            self.coef.append((q0, v0, 0.5 * a0, (10.0 * h - 4.0 * dv * T + 0.5 * da * T * T) / T ** 3,
                              (-15.0 * h + 7.0 * dv * T - da * T * T) / T ** 4,
                              (6.0 * h - 3.0 * dv * T + 0.5 * da * T * T) / T ** 5))

    def sample(self, t_s: float) -> tuple[Pair, Pair, Pair]:
        tau = min(max(t_s + self.T, 0.0), self.T)
        out = []
        for c in self.coef:
            q = c[0] + tau * (c[1] + tau * (c[2] + tau * (c[3] + tau * (c[4] + tau * c[5]))))
            qd = c[1] + tau * (2 * c[2] + tau * (3 * c[3] + tau * (4 * c[4] + tau * 5 * c[5])))
            qdd = 2 * c[2] + tau * (6 * c[3] + tau * (12 * c[4] + tau * 20 * c[5]))
            out.append((q, qd, qdd))
        return (out[0][0], out[1][0]), (out[0][1], out[1][1]), (out[0][2], out[1][2])


class Trigger:
    """Event when ||eps(t_i) - eps(t)|| >= eta / (L sqrt(1 + c^2)) (Eq. 19), ||X~|| > r, or max_inter_event_s
    passed (heartbeat); eps = (x~1, x~2 of both joints, x_d, xdot_d of both joints). `tt`: every sample."""

    def __init__(self, trigger: dict[str, Any], c: float, mode: str = "et") -> None:
        self.mode = mode
        self.threshold = trigger["eta"] / (trigger["lipschitz_l"] * math.sqrt(1.0 + c * c))
        self.r = trigger["r"]
        self.max_inter_event_ns = int(round(trigger["max_inter_event_s"] * 1e9))
        self._eps_i: tuple[float, ...] | None = None
        self._t_i_ns = 0

    def update(self, t_ns: int, eps: tuple[float, ...]) -> str | None:
        if self.mode == "tt":
            return "TIME"
        if self._eps_i is None:
            reason: str | None = "INITIAL"
        else:
            acc = 0.0
            for u, v in zip(self._eps_i, eps, strict=True):
                acc += (u - v) * (u - v)
            x_norm = math.sqrt(eps[0] * eps[0] + eps[1] * eps[1] + eps[2] * eps[2] + eps[3] * eps[3])
            if math.sqrt(acc) >= self.threshold:
                reason = "ERROR_BOUND"
            elif x_norm > self.r:
                reason = "TRACKING_BOUND"
            elif t_ns - self._t_i_ns >= self.max_inter_event_ns:
                reason = "HEARTBEAT"
            else:
                reason = None
        if reason is not None:
            self._eps_i, self._t_i_ns = eps, t_ns
        return reason


class Decision(NamedTuple):
    t_ns: int                           # controller time of the state (t < 0: lead-in)
    desired: tuple[Pair, Pair, Pair]    # theta_d, omega_d, alpha_d
    reason: str | None                  # trigger reason name, None: no event
    deflection_m: Pair | None           # v_x(t_i) on an event
    sliding: Pair | None                # s(t_i) on an event


class OuterLoop:
    """The whole outer loop for one state: time axis (t = 0 at the first state's sample time + lead-in), desired
    motion (lead-in, then the gait), trigger and, on an event, the SMC. From the session config (a dict)."""

    def __init__(self, cfg: dict[str, Any], cycles: int, mode: str = "et") -> None:
        cc, tr = cfg["controller"], cfg["trajectory"]
        if tr["kind"] != "gait":
            raise ValueError(f"this example follows the built-in gait only, not trajectory.kind = {tr['kind']!r}")
        self.c, self.rho, self.bl = cc["c"], cc["rho"], cc["boundary_layer"]
        self.limb, self.gait = Limb(cfg["plant"]), Gait(tr["period_s"])
        self.trigger = Trigger(cfg["trigger"], self.c, mode)
        self.lead_in_ns = int(round(tr["lead_in_s"] * 1e9))
        self.duration_ns = int(round(tr["period_s"] * cycles * 1e9))
        self.t0_ns: int | None = None
        self.lead_in: LeadIn | None = None

    def step(self, sample_t_ns: int, theta: Pair, omega: Pair) -> Decision | None:
        """The decision for a new state; None once its time is past the cycles (stop answering). An absurd state
        may raise ArithmeticError/ValueError from the model (the caller counts it)."""
        if self.t0_ns is None:
            self.t0_ns = sample_t_ns + self.lead_in_ns
            if self.lead_in_ns:
                self.lead_in = LeadIn(theta, omega, self.gait.sample(0.0), self.lead_in_ns * 1e-9)
        t_ns = sample_t_ns - self.t0_ns
        if t_ns > self.duration_ns:
            return None
        des = self.lead_in.sample(t_ns * 1e-9) if t_ns < 0 and self.lead_in else self.gait.sample(t_ns * 1e-9)
        x = (theta[0] - des[0][0], theta[1] - des[0][1], omega[0] - des[1][0], omega[1] - des[1][1])
        reason = self.trigger.update(t_ns, (*x, *des[0], *des[1]))
        if reason is None:
            return Decision(t_ns, des, None, None, None)
        vx, s = smc(self.limb, theta, omega, des, self.c, self.rho, self.bl)
        return Decision(t_ns, des, reason, vx, s)

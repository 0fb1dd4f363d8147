"""SEA limb dynamics (paper Eq. 1-9) as a pure function and its RK4 step, shared by the plant emulator's truth and the
controller's nominal model (the predictor of issue 16, `controller/predictor.py`): SEA nut dynamics (Eq. 6),
disturbance torques, mechanical end stops and voltage saturation.

State x = (theta1, theta2, omega1, omega2, r1, r2, rdot1, rdot2): joint angles/velocities and ball-screw nut
displacements/velocities. Spring deflection Delta_i = r_Bi - r_i with r_Bi = L_Si(theta) - L_Si(theta_ref) (Eq. 7).
"""
from __future__ import annotations

import math

from sea_hil.mechanics import LimbParams, mass_matrix, n_terms, sea_geometry, solve_m

State = tuple[float, float, float, float, float, float, float, float]


def saturate(voltage_v: float, limit_v: float) -> float:
    if voltage_v != voltage_v:  # NaN never reaches the motor
        return 0.0
    return limit_v if voltage_v > limit_v else (-limit_v if voltage_v < -limit_v else voltage_v)


def deflections(x: State, p: LimbParams) -> tuple[float, float, float, float]:
    """(Delta1, Delta2, Delta1_dot, Delta2_dot) of state x."""
    len1, len2, a1, a2, _, _ = sea_geometry(x[0], x[1], p)
    return (len1 - p.l_ref[0] - x[4], len2 - p.l_ref[1] - x[5], a1 * x[2] - x[6], a2 * x[3] - x[7])


def end_stop_torque(q: float, w: float, lo: float, hi: float, k: float, c: float) -> float:
    """Torque (Nm) of one joint's mechanical end stops at angle q, velocity w: a spring-damper (k Nm/rad, c Nms/rad)
    acting on the penetration beyond [lo, hi], exactly 0.0 inside. It pushes back and never pulls (no adhesion: the
    force is clamped at zero when the damper would hold the joint against the stop), so its non-conservative part
    only dissipates: power = -c w^2 while not clamped, k p w <= 0 while clamped (p the penetration, moving out)."""
    if q > hi:
        return -max(0.0, k * (q - hi) + c * w)
    if q < lo:
        return max(0.0, k * (lo - q) - c * w)
    return 0.0


def end_stop_energy(x: State, p: LimbParams) -> float:
    """Potential energy (J) stored in the end stops' springs at state x (0 inside the stops)."""
    e = 0.0
    for j in range(2):
        pen = max(x[j] - p.stop_max_rad[j], p.stop_min_rad[j] - x[j], 0.0)
        e += 0.5 * p.stop_k_nm_per_rad[j] * pen * pen
    return e


def f(t: float, x: State, u: tuple[float, float], p: LimbParams,
      d_nm: tuple[float, float] = (0.0, 0.0)) -> State:
    """dx/dt for applied (already saturated) voltages u and disturbance torques d_nm (Eq. 3-6), plus the end-stop
    torques (zero inside the stops, so on the trajectory this is Eq. 3-6 exactly)."""
    q1, q2, w1, w2, r1, r2, rd1, rd2 = x
    len1, len2, a1, a2, _, _ = sea_geometry(q1, q2, p)
    tau1 = -p.k1 * (len1 - p.l_ref[0] - r1) * a1
    tau2 = -p.k2 * (len2 - p.l_ref[1] - r2) * a2
    n1, n2 = n_terms(q1, q2, w1, w2, p)
    m11, m12, m22 = mass_matrix(q2, p)
    s1 = end_stop_torque(q1, w1, p.stop_min_rad[0], p.stop_max_rad[0], p.stop_k_nm_per_rad[0], p.stop_c_nms_per_rad[0])
    s2 = end_stop_torque(q2, w2, p.stop_min_rad[1], p.stop_max_rad[1], p.stop_k_nm_per_rad[1], p.stop_c_nms_per_rad[1])
    acc1, acc2 = solve_m(m11, m12, m22, tau1 + n1 + d_nm[0] + s1, tau2 + n2 + d_nm[1] + s2)
    c = p.nut_damping
    return (w1, w2, acc1, acc2, rd1, rd2, u[0] - c * rd1, u[1] - c * rd2)


def equilibrium_nut(q1: float, q2: float, p: LimbParams) -> tuple[float, float]:
    """Nut positions that hold the limb static at (q1, q2) against gravity (used for the initial state)."""
    len1, len2, a1, a2, _, _ = sea_geometry(q1, q2, p)
    n1, n2 = n_terms(q1, q2, 0.0, 0.0, p)
    # tau + N = 0  ->  -k Delta a = -N  ->  Delta = N / (k a)
    delta1, delta2 = n1 / (p.k1 * a1), n2 / (p.k2 * a2)
    return len1 - p.l_ref[0] - delta1, len2 - p.l_ref[1] - delta2


def initial_state(q1: float, q2: float, w1: float, w2: float, p: LimbParams) -> State:
    r1, r2 = equilibrium_nut(q1, q2, p)
    return (q1, q2, w1, w2, r1, r2, 0.0, 0.0)


def is_finite(x: State) -> bool:
    for v in x:  # explicit loop: also compiles in the offline simulation's numba kernel
        if not math.isfinite(v):
            return False
    return True


def rk4_core(t: float, x: State, u: tuple[float, float], h: float, p: LimbParams, d0: tuple[float, float],
             dm: tuple[float, float], d1: tuple[float, float]) -> State:
    """One classical RK4 step of length h (seconds) with disturbance torques d0, dm, d1 at t, t + h/2, t + h."""
    hh = 0.5 * h
    x0, x1, x2, x3, x4, x5, x6, x7 = x
    k1 = f(t, x, u, p, d0)
    k2 = f(t + hh, (x0 + hh * k1[0], x1 + hh * k1[1], x2 + hh * k1[2], x3 + hh * k1[3],
                    x4 + hh * k1[4], x5 + hh * k1[5], x6 + hh * k1[6], x7 + hh * k1[7]), u, p, dm)
    k3 = f(t + hh, (x0 + hh * k2[0], x1 + hh * k2[1], x2 + hh * k2[2], x3 + hh * k2[3],
                    x4 + hh * k2[4], x5 + hh * k2[5], x6 + hh * k2[6], x7 + hh * k2[7]), u, p, dm)
    k4 = f(t + h, (x0 + h * k3[0], x1 + h * k3[1], x2 + h * k3[2], x3 + h * k3[3],
                   x4 + h * k3[4], x5 + h * k3[5], x6 + h * k3[6], x7 + h * k3[7]), u, p, d1)
    h6 = h / 6.0
    return (x0 + h6 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            x1 + h6 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
            x2 + h6 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
            x3 + h6 * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3]),
            x4 + h6 * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4]),
            x5 + h6 * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5]),
            x6 + h6 * (k1[6] + 2.0 * k2[6] + 2.0 * k3[6] + k4[6]),
            x7 + h6 * (k1[7] + 2.0 * k2[7] + 2.0 * k3[7] + k4[7]))

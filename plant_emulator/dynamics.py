"""Plant dynamics (paper Eq. 1-9) as a pure function, plus the plant-only parts: SEA nut dynamics (Eq. 6),
disturbance torques and voltage saturation.

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


def f(t: float, x: State, u: tuple[float, float], p: LimbParams,
      d_nm: tuple[float, float] = (0.0, 0.0)) -> State:
    """dx/dt for applied (already saturated) voltages u and disturbance torques d_nm (Eq. 3-6)."""
    q1, q2, w1, w2, r1, r2, rd1, rd2 = x
    len1, len2, a1, a2, _, _ = sea_geometry(q1, q2, p)
    tau1 = -p.k1 * (len1 - p.l_ref[0] - r1) * a1
    tau2 = -p.k2 * (len2 - p.l_ref[1] - r2) * a2
    n1, n2 = n_terms(q1, q2, w1, w2, p)
    m11, m12, m22 = mass_matrix(q2, p)
    acc1, acc2 = solve_m(m11, m12, m22, tau1 + n1 + d_nm[0], tau2 + n2 + d_nm[1])
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

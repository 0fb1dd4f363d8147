"""Limb mechanics shared by the plant emulator and the controller's nominal model (paper Eq. 1-5 and 8).

These functions give the wire quantities their meaning: the spring deflection Delta = r_B - r (Eq. 7) needs the SEA
length L_S(theta) of Eq. 1, and the controller's setpoint v_x is such a deflection. Everything here is a pure function
of plain floats (no numpy) because it sits on the 1 kHz hot path.

Conventions (derived from Eq. 2, see docs/model.md): theta1 is the hip angle of link 1 from the downward vertical;
theta2 is the knee angle measured so that link 2's absolute angle is theta1 - theta2. Moment arms a_i = dL_Si/dtheta_i
(= d4 sin(gamma1), d9 sin(gamma2) by the law of sines), and the SEA torque is tau_i = -k_i Delta_i a_i (Eq. 4).
"""
from __future__ import annotations

import math
from typing import NamedTuple

from sea_hil.config.model import PlantConfig


class LimbParams(NamedTuple):
    """Plain-float parameters with derived constants precomputed for the hot path (a NamedTuple so that the
    offline simulation can hand it to a numba-compiled kernel unchanged)."""
    d: tuple[float, ...]
    r1: float
    r2: float
    l1: float
    m1: float
    m2: float
    i1: float
    i2: float
    k1: float
    k2: float
    b1: float
    b2: float
    g: float
    alpha1: float
    alpha2: float
    sigma1: float
    sigma2: float
    theta_ref: tuple[float, float]
    l_ref: tuple[float, float]
    nut_damping: float
    voltage_limit: float
    # derived
    m11_const: float
    m12_const: float
    m22: float
    b_coupling: float
    grav1: float
    grav2: float
    # mechanical end stops of the plant (`[plant.end_stops]`; +-inf: none), used by the plant model only
    stop_min_rad: tuple[float, float] = (-math.inf, -math.inf)
    stop_max_rad: tuple[float, float] = (math.inf, math.inf)
    stop_k_nm_per_rad: tuple[float, float] = (0.0, 0.0)
    stop_c_nms_per_rad: tuple[float, float] = (0.0, 0.0)


def limb_params(cfg: PlantConfig) -> LimbParams:
    d = tuple(float(v) for v in cfg.d_m)
    d1, d2, _, _, _, d6, d7 = d[0], d[1], d[2], d[3], d[4], d[5], d[6]
    sigma1 = math.atan2(d2, d1)
    sigma2 = math.atan2(d7, d6)
    i2_c = cfg.i2_kgm2 if cfg.include_i2_in_coupling else 0.0
    m2r2sq = cfg.m2_kg * cfg.r2_m**2
    partial = LimbParams(
        d=d, r1=cfg.r1_m, r2=cfg.r2_m, l1=cfg.l1_m, m1=cfg.m1_kg, m2=cfg.m2_kg, i1=cfg.i1_kgm2, i2=cfg.i2_kgm2,
        k1=cfg.k1_n_per_m, k2=cfg.k2_n_per_m, b1=cfg.b1_nms, b2=cfg.b2_nms, g=cfg.g_m_s2,
        alpha1=cfg.alpha1_rad, alpha2=cfg.alpha2_rad, sigma1=sigma1, sigma2=sigma2,
        theta_ref=cfg.theta_ref_rad, l_ref=(0.0, 0.0),
        nut_damping=cfg.nut_damping_per_s, voltage_limit=cfg.voltage_limit_v,
        m11_const=cfg.m1_kg * cfg.r1_m**2 + cfg.i1_kgm2 + cfg.m2_kg * cfg.l1_m**2 + m2r2sq + i2_c,
        m12_const=m2r2sq + i2_c,
        m22=m2r2sq + cfg.i2_kgm2,
        b_coupling=cfg.m2_kg * cfg.l1_m * cfg.r2_m,
        grav1=(cfg.m1_kg * cfg.r1_m + cfg.m2_kg * cfg.l1_m) * cfg.g_m_s2,
        grav2=cfg.m2_kg * cfg.r2_m * cfg.g_m_s2,
    )
    stops = cfg.end_stops
    if stops.enabled:
        partial = partial._replace(stop_min_rad=stops.min_rad, stop_max_rad=stops.max_rad,
                                   stop_k_nm_per_rad=stops.stiffness_nm_per_rad,
                                   stop_c_nms_per_rad=stops.damping_nms_per_rad)
    return partial._replace(l_ref=sea_lengths(partial.theta_ref[0], partial.theta_ref[1], partial))


def apex_angles(q1: float, q2: float, p: LimbParams) -> tuple[float, float]:
    """Triangle angles at O1 and O2 opposite the SEA (the cosine-rule arguments of Eq. 1)."""
    return (0.5 * math.pi - p.sigma1 + q1 - p.alpha1, math.pi - p.sigma2 + q2 - p.alpha2)


def sea_lengths(q1: float, q2: float, p: LimbParams) -> tuple[float, float]:
    """Eq. 1, cosine-rule form."""
    d3, d4, d8, d9 = p.d[2], p.d[3], p.d[7], p.d[8]
    b1, b2 = apex_angles(q1, q2, p)
    return (math.sqrt(d3 * d3 + d4 * d4 - 2.0 * d3 * d4 * math.cos(b1)),
            math.sqrt(d8 * d8 + d9 * d9 - 2.0 * d8 * d9 * math.cos(b2)))


def sea_lengths_expanded(q1: float, q2: float, p: LimbParams) -> tuple[float, float]:
    """Eq. 1, second (expanded) form; equal to `sea_lengths` iff sigma1 = atan2(d2, d1), sigma2 = atan2(d7, d6)."""
    d1, d2, d3, d4, d6, d7, d8, d9 = p.d[0], p.d[1], p.d[2], p.d[3], p.d[5], p.d[6], p.d[7], p.d[8]
    a1, a2 = q1 - p.alpha1, p.alpha2 - q2
    return (math.sqrt(d4 * d4 + d3 * d3 - 2.0 * d4 * (d2 * math.cos(a1) - d1 * math.sin(a1))),
            math.sqrt(d8 * d8 + d9 * d9 - 2.0 * d9 * (d7 * math.sin(a2) - d6 * math.cos(a2))))


def sea_geometry(q1: float, q2: float, p: LimbParams) -> tuple[float, float, float, float, float, float]:
    """(L1, L2, a1, a2, a1', a2'): SEA lengths, moment arms dL/dtheta and their derivatives d2L/dtheta2."""
    d3, d4, d8, d9 = p.d[2], p.d[3], p.d[7], p.d[8]
    b1, b2 = apex_angles(q1, q2, p)
    c1, s1, c2, s2 = math.cos(b1), math.sin(b1), math.cos(b2), math.sin(b2)
    k1, k2 = d3 * d4, d8 * d9
    len1 = math.sqrt(d3 * d3 + d4 * d4 - 2.0 * k1 * c1)
    len2 = math.sqrt(d8 * d8 + d9 * d9 - 2.0 * k2 * c2)
    a1, a2 = k1 * s1 / len1, k2 * s2 / len2
    return len1, len2, a1, a2, (k1 * c1 - a1 * a1) / len1, (k2 * c2 - a2 * a2) / len2


def mass_matrix(q2: float, p: LimbParams) -> tuple[float, float, float]:
    """(M11, M12, M22) of Eq. 2 so that M = [[M11, -M12], [-M12, M22]] (M21 = M12)."""
    bc = p.b_coupling * math.cos(q2)
    return p.m11_const + 2.0 * bc, p.m12_const + bc, p.m22


def n_terms(q1: float, q2: float, w1: float, w2: float, p: LimbParams) -> tuple[float, float]:
    """N1, N2 of Eq. 2 (gravity, Coriolis/centrifugal, viscous friction)."""
    bs = p.b_coupling * math.sin(q2)
    sg = math.sin(q2 - q1)
    n1 = -p.grav1 * math.sin(q1) + p.grav2 * sg - bs * (w2 * w2 - 2.0 * w1 * w2) - p.b1 * w1
    n2 = -p.grav2 * sg - bs * w1 * w1 - p.b2 * w2
    return n1, n2


def solve_m(m11: float, m12: float, m22: float, y1: float, y2: float) -> tuple[float, float]:
    """Solve [[m11, -m12], [-m12, m22]] x = y."""
    det = m11 * m22 - m12 * m12
    return (m22 * y1 + m12 * y2) / det, (m12 * y1 + m11 * y2) / det


def fx_gx(q1: float, q2: float, w1: float, w2: float, a1: float, a2: float, p: LimbParams
          ) -> tuple[float, float, tuple[float, float, float, float]]:
    """f_x = M^-1 N and g_x = M^-1 diag(-k1 a1, -k2 a2) (Eq. 8); g_x returned row-major (g11, g12, g21, g22)."""
    m11, m12, m22 = mass_matrix(q2, p)
    n1, n2 = n_terms(q1, q2, w1, w2, p)
    det = m11 * m22 - m12 * m12
    f1, f2 = (m22 * n1 + m12 * n2) / det, (m12 * n1 + m11 * n2) / det
    e1, e2 = -p.k1 * a1, -p.k2 * a2
    return f1, f2, (m22 * e1 / det, m12 * e2 / det, m12 * e1 / det, m11 * e2 / det)


def energy(x: tuple[float, ...] | list[float], p: LimbParams) -> float:
    """Kinetic + gravitational + spring energy of plant state x = (q1, q2, w1, w2, r1, r2, rd1, rd2)."""
    q1, q2, w1, w2, r1, r2 = x[0], x[1], x[2], x[3], x[4], x[5]
    m11, m12, m22 = mass_matrix(q2, p)
    kin = 0.5 * (m11 * w1 * w1 - 2.0 * m12 * w1 * w2 + m22 * w2 * w2)
    pot = -p.grav1 * math.cos(q1) - p.grav2 * math.cos(q1 - q2)
    len1, len2 = sea_lengths(q1, q2, p)
    dl1 = len1 - p.l_ref[0] - r1
    dl2 = len2 - p.l_ref[1] - r2
    return kin + pot + 0.5 * p.k1 * dl1 * dl1 + 0.5 * p.k2 * dl2 * dl2

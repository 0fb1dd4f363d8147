"""Sliding surface and SMC law, paper Eq. 12-13, on the nominal model (sea_hil.mechanics).

The law returns v_x, the desired spring deflection of each SEA (metres). Pure functions of plain floats.
"""
from __future__ import annotations

from typing import NamedTuple

from sea_hil.controller.trajectory import DesiredSample
from sea_hil.mechanics import LimbParams, mass_matrix, n_terms, sea_geometry


class JointState(NamedTuple):
    """What the outer loop needs of a measurement: joint angles and velocities (a NamedTuple: made several times per
    outer sample, a third of a frozen dataclass's construction time)."""
    theta_rad: tuple[float, float]
    omega_rad_s: tuple[float, float]


def switching(s: float, boundary_layer: float) -> float:
    """sign(s) as in the paper (boundary_layer = 0), else the saturation sat(s / boundary_layer)."""
    if boundary_layer <= 0.0:
        return 1.0 if s > 0.0 else (-1.0 if s < 0.0 else 0.0)
    v = s / boundary_layer
    return 1.0 if v > 1.0 else (-1.0 if v < -1.0 else v)


def tracking_errors(js: JointState, ds: DesiredSample) -> tuple[float, float, float, float]:
    """(x~1_hip, x~1_knee, x~2_hip, x~2_knee) of Eq. 11."""
    return tracking_error(js.theta_rad, js.omega_rad_s, ds.theta_rad, ds.omega_rad_s)


def tracking_error(theta_rad: tuple[float, float], omega_rad_s: tuple[float, float],
                   theta_d_rad: tuple[float, float], omega_d_rad_s: tuple[float, float]
                   ) -> tuple[float, float, float, float]:
    """`tracking_errors` on plain pairs (compiled in the offline session kernel)."""
    return (theta_rad[0] - theta_d_rad[0], theta_rad[1] - theta_d_rad[1],
            omega_rad_s[0] - omega_d_rad_s[0], omega_rad_s[1] - omega_d_rad_s[1])


def sliding_surface(xt: tuple[float, float, float, float], c: float) -> tuple[float, float]:
    """Eq. 12: s = c x~1 + x~2."""
    return c * xt[0] + xt[2], c * xt[1] + xt[3]


def smc_deflection(js: JointState, ds: DesiredSample, p: LimbParams, c: float, rho: float,
                   boundary_layer: float = 0.0) -> tuple[tuple[float, float], tuple[float, float]]:
    """Eq. 13: v_x = g_x^-1 [-f_x + xdd_d - c x~2 - rho sign(s)]. Returns (v_x, s)."""
    return smc_law(js.theta_rad, js.omega_rad_s, ds.theta_rad, ds.omega_rad_s, ds.alpha_rad_s2, p, c, rho,
                   boundary_layer)


def smc_law(theta_rad: tuple[float, float], omega_rad_s: tuple[float, float], theta_d_rad: tuple[float, float],
            omega_d_rad_s: tuple[float, float], alpha_d_rad_s2: tuple[float, float], p: LimbParams, c: float,
            rho: float, boundary_layer: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """`smc_deflection` on plain pairs (the live controller runs it; the offline session kernel compiles it).

    With f_x = M^-1 N and g_x = M^-1 diag(-k a): v_x = diag(-k a)^-1 (M y - N), y = xdd_d - c x~2 - rho sign(s).
    """
    q1, q2 = theta_rad
    w1, w2 = omega_rad_s
    xt = tracking_error(theta_rad, omega_rad_s, theta_d_rad, omega_d_rad_s)
    s = sliding_surface(xt, c)
    y1 = alpha_d_rad_s2[0] - c * xt[2] - rho * switching(s[0], boundary_layer)
    y2 = alpha_d_rad_s2[1] - c * xt[3] - rho * switching(s[1], boundary_layer)
    m11, m12, m22 = mass_matrix(q2, p)
    n1, n2 = n_terms(q1, q2, w1, w2, p)
    _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
    v1 = (m11 * y1 - m12 * y2 - n1) / (-p.k1 * a1)
    v2 = (-m12 * y1 + m22 * y2 - n2) / (-p.k2 * a2)
    return (v1, v2), s

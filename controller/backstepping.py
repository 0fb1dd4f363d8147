"""Backstepping inner loop, paper Eq. 24-31: from the held deflection setpoint v_x(t_i) to the SEA voltage U_v.

z1 = Delta (measured spring deflection), z2 = Delta_dot = a(theta) omega - rdot. With v_x(t_i) held between events,
its time derivative is zero. The cross term -(g_x)^T s of Eq. 27 is weighted by `w` (see `cross_term_weight` and
docs/deviations.md): the augmented Lyapunov function V1 = V_x + (1/(2w)) |v_x - z1|^2 cancels it for any w > 0, and
w = 1 (the paper) makes it ~1e4-1e5 times too large for these units.

Disturbance compensation (docs/deviations.md section 10; `controller.disturbance_compensation`): the joint
acceleration f_x + g_x z1 inside F_R (f_2 of Eq. 28/31) has no disturbance, so a torque d biases the deflection
dynamics by a M^-1 d, which the loop turns into a deflection error ~ a M^-1 d / (kp1 kp2), i.e. a joint torque error
~ k a^2 M^-1 d / (kp1 kp2) (about 6 d at the knee). With the observer's estimate (controller/observer.py), 'inner' adds
M^-1 d_hat to that acceleration; 'full' also adds the deflection c = d_hat / (k a) to v_x, which cancels d at the
joint, so the outer SMC sees the nominal plant. c is not held like v_x(t_i): Eq. 27's vdot_x term carries the
observer's rate c', and so does v1' (kp1 c'), so the deflection loop tracks c without most of its own lag (kp1, kp2
poles at 60 and 100 rad/s: 0.34 rad at 2 Hz). c'' (the observer's w0^3 e) is left out of v1': it gains little and
saturates the drive under stepwise (held-noise) torques. 'off' (compensation = 0) is the paper's law, computed
exactly as before.
"""
from __future__ import annotations

from typing import NamedTuple

from sea_hil.controller.observer import Estimate
from sea_hil.mechanics import LimbParams, fx_gx, mass_matrix, sea_geometry, solve_m

Measurement = tuple[float, float, float, float, float, float, float, float]
"""(theta1, theta2, omega1, omega2, delta1, delta2, nut_vel1, nut_vel2) as sent by the driver."""

_FD_STEP_S = 1e-4  # finite-difference horizon for g_x_dot along the current joint velocity
COMPENSATION = {"off": 0, "inner": 1, "full": 2}
NO_ESTIMATE: Estimate = (0.0, 0.0, 0.0, 0.0)


class InnerGains(NamedTuple):
    kp1: float
    kp2: float
    w: float  # cross-term weight (1.0 = paper)
    compensation: int = 0  # COMPENSATION[controller.disturbance_compensation]; 0 = paper
    observer_rad_s: float = 0.0  # disturbance observer pole (used when compensation > 0)


def cross_term_weight(mode: str, p: LimbParams, bandwidth_rad_s: float, theta_rad: tuple[float, float]) -> float:
    """'paper' -> 1; 'off' -> 0; 'normalized' -> omega_c^2 / ||g_x(theta)||_F^2.

    The cross term couples s and the deflection error e1 = v_x - z1 into an oscillator s'' + w |g|^2 s = ...,
    whose frequency is sqrt(w) |g_x|. With w = 1 (paper) that is ~3e4 rad/s, far beyond any sampled loop; the
    normalized weight places it at omega_c (a design bandwidth, rad/s) while keeping the Lyapunov cancellation.
    """
    if mode == "paper":
        return 1.0
    if mode == "off":
        return 0.0
    q1, q2 = theta_rad
    _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
    _, _, g = fx_gx(q1, q2, 0.0, 0.0, a1, a2, p)
    return bandwidth_rad_s * bandwidth_rad_s / sum(v * v for v in g)


def _cross(g: tuple[float, float, float, float], s: tuple[float, float]) -> tuple[float, float]:
    """g^T s for row-major g."""
    return g[0] * s[0] + g[2] * s[1], g[1] * s[0] + g[3] * s[1]


def backstepping_voltage(m: Measurement, vx: tuple[float, float], s: tuple[float, float], p: LimbParams,
                         gains: InnerGains, d_hat: Estimate = NO_ESTIMATE) -> tuple[float, float]:
    """Eq. 27 and 31 (unsaturated U_v in volts). d_hat = (d1, d2, d1', d2'), the observer's lumped joint torques
    (N m) and their rates, is used only when gains.compensation > 0."""
    q1, q2, w1, w2, z11, z12, rd1, rd2 = m
    _, _, a1, a2, a1p, a2p = sea_geometry(q1, q2, p)
    f1, f2, g = fx_gx(q1, q2, w1, w2, a1, a2, p)
    z21, z22 = a1 * w1 - rd1, a2 * w2 - rd2
    e11, e12 = vx[0] - z11, vx[1] - z12
    # nominal joint acceleration and SEA end acceleration F_R = d2 r_B / dt2
    acc1 = f1 + g[0] * z11 + g[1] * z12
    acc2 = f2 + g[2] * z11 + g[3] * z12
    if gains.compensation > 0:
        m11, m12, m22 = mass_matrix(q2, p)
        da1, da2 = solve_m(m11, m12, m22, d_hat[0], d_hat[1])
        acc1 += da1
        acc2 += da2
        if gains.compensation > 1:  # extra deflection c = d_hat / (k a): its spring torque -k a c cancels d_hat
            e11 += d_hat[0] / (p.k1 * a1)
            e12 += d_hat[1] / (p.k2 * a2)
    cr1 = cr2 = 0.0  # rate of the compensating deflection (compensation 2)
    if gains.compensation > 1:
        cr1 = _compensation_rate(d_hat[0], d_hat[2], p.k1, a1, a1p * w1)
        cr2 = _compensation_rate(d_hat[1], d_hat[3], p.k2, a2, a2p * w2)
    fr1, fr2 = a1 * acc1 + a1p * w1 * w1, a2 * acc2 + a2p * w2 * w2
    if gains.w != 0.0:
        c1, c2 = _cross(g, s)
        gd = _g_dot(q1, q2, w1, w2, p)
        cd1, cd2 = _cross(gd, s)
        c1, c2, cd1, cd2 = gains.w * c1, gains.w * c2, gains.w * cd1, gains.w * cd2
    else:
        c1 = c2 = cd1 = cd2 = 0.0
    v11 = gains.kp1 * e11 + cr1 - c1    # Eq. 27: vdot_x(t_i) = 0 (held setpoint), the compensation's rate cr
    v12 = gains.kp1 * e12 + cr2 - c2
    v1d1 = gains.kp1 * (cr1 - z21) - cd1   # time derivative of v1 (s held; the c'' term left out, see above)
    v1d2 = gains.kp1 * (cr2 - z22) - cd2
    cn = p.nut_damping
    u1 = fr1 + cn * rd1 - gains.kp2 * (v11 - z21) - v1d1 - e11   # Eq. 31 with g2 = -1
    u2 = fr2 + cn * rd2 - gains.kp2 * (v12 - z22) - v1d2 - e12
    return u1, u2


def _compensation_rate(d: float, d_dot: float, k: float, a: float, a_dot: float) -> float:
    """c' of the compensating deflection c = d / (k a) along the joint motion (a_dot = a' omega)."""
    return d_dot / (k * a) - d * a_dot / (k * a * a)


def _g_dot(q1: float, q2: float, w1: float, w2: float, p: LimbParams) -> tuple[float, float, float, float]:
    h = _FD_STEP_S
    _, _, a1, a2, _, _ = sea_geometry(q1 + w1 * h, q2 + w2 * h, p)
    _, _, gp = fx_gx(q1 + w1 * h, q2 + w2 * h, 0.0, 0.0, a1, a2, p)
    _, _, a1, a2, _, _ = sea_geometry(q1 - w1 * h, q2 - w2 * h, p)
    _, _, gm = fx_gx(q1 - w1 * h, q2 - w2 * h, 0.0, 0.0, a1, a2, p)
    h2 = 2.0 * h
    return (gp[0] - gm[0]) / h2, (gp[1] - gm[1]) / h2, (gp[2] - gm[2]) / h2, (gp[3] - gm[3]) / h2


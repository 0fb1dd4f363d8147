"""Momentum disturbance observer at the edge (docs/deviations.md section 10).

The generalised momentum P = M(theta) omega of Eq. 2 obeys dP/dt = Mdot omega + tau + N + d with tau = -k a Delta
(Eq. 4), so an observer of P driven by the model plus its estimate d_hat recovers the lumped joint torque d (external
torque plus every nominal-model error) through the momentum error, without differentiating the measured velocity. Everything here uses the nominal model and the 1 kHz measurement only.
Plain float code: the offline closed loop compiles it with numba from this source (sea_hil/offline/closed_loop.py).
"""
from __future__ import annotations

import math

from sea_hil.mechanics import LimbParams, mass_matrix, n_terms, sea_geometry

ObserverState = tuple[float, float, float, float, float, float, float, float, float, float]
"""(xi1, xi2, d_hat1, d_hat2, d_hat_dot1, d_hat_dot2, e1, e2, f1, f2): predicted momentum (N m s), the lumped-torque
estimate (N m) and its rate (N m/s), the last momentum error and model torque. NaN xi = not started."""

OBSERVER_UNSTARTED: ObserverState = (math.nan, math.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def momentum(q2: float, w1: float, w2: float, p: LimbParams) -> tuple[float, float]:
    """P = M(theta) omega with M = [[M11, -M12], [-M12, M22]]."""
    m11, m12, m22 = mass_matrix(q2, p)
    return m11 * w1 - m12 * w2, -m12 * w1 + m22 * w2


def observer_step(m: tuple[float, float, float, float, float, float, float, float], obs: ObserverState,
                  p: LimbParams, bandwidth_rad_s: float, dt_s: float) -> ObserverState:
    """Second-order (extended-state) momentum observer, both poles at -bandwidth_rad_s:
    e = P - xi, xi' = F + d_hat + 2 w0 e with the model torque F = Mdot omega + tau + N, d_hat' = w0^2 e, so that
    d_hat'' + 2 w0 d_hat' + w0^2 d_hat = w0^2 d (no lag for a ramp) and d_hat' = w0^2 e comes without differencing.
    Discretised at each measurement: xi advances over the last period with the trapezoid of F (the SEA torque
    changes within a period), then e, d_hat and d_hat' are updated. The first call starts xi at the measured
    momentum (d_hat = 0)."""
    q1, q2, w1, w2, z1, z2 = m[0], m[1], m[2], m[3], m[4], m[5]
    p1, p2 = momentum(q2, w1, w2, p)
    _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
    n1, n2 = n_terms(q1, q2, w1, w2, p)
    bs = p.b_coupling * math.sin(q2)
    f1 = -p.k1 * z1 * a1 + n1 + bs * w2 * (w2 - 2.0 * w1)   # (dM/dt) omega: dM11/dt = -2 b sin(q2) w2,
    f2 = -p.k2 * z2 * a2 + n2 + bs * w2 * w1                # dM12/dt = -b sin(q2) w2
    if obs[0] != obs[0]:  # NaN: not started
        return p1, p2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f1, f2
    l1, l2 = 2.0 * bandwidth_rad_s, bandwidth_rad_s * bandwidth_rad_s
    xi1 = obs[0] + dt_s * (0.5 * (obs[8] + f1) + obs[2] + l1 * obs[6])
    xi2 = obs[1] + dt_s * (0.5 * (obs[9] + f2) + obs[3] + l1 * obs[7])
    e1, e2 = p1 - xi1, p2 - xi2
    dd1, dd2 = l2 * e1, l2 * e2
    return xi1, xi2, obs[2] + dt_s * dd1, obs[3] + dt_s * dd2, dd1, dd2, e1, e2, f1, f2

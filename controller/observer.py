"""Momentum disturbance observer at the edge (docs/deviations.md section 10).

The generalised momentum P = M(theta) omega of Eq. 2 obeys dP/dt = Mdot omega + tau + N + d with tau = -k a Delta
(Eq. 4), so an observer of P driven by the model plus its estimate d_hat recovers the lumped joint torque d (external
torque plus every nominal-model error) through the momentum error, without differentiating the measured velocity.
Everything here uses the nominal model and the 1 kHz measurement only.
Plain float code: the offline closed loop compiles it with numba from this source (sea_hil/offline/closed_loop.py).
"""
from __future__ import annotations

import math

from sea_hil.mechanics import LimbParams, mass_matrix, n_terms, sea_geometry

ObserverState = tuple[float, float, float, float, float, float]
"""(xi1, xi2, d_hat1, d_hat2, d_rate1, d_rate2): momentum estimate (N m s), the lumped-torque estimate (N m) and its
rate (N m/s), all for the time of the next measurement. NaN xi = not started."""

Estimate = tuple[float, float, float, float]
"""(d1, d2, d1_dot, d2_dot): the lumped torque (N m) and its rate (N m/s) at the time of this measurement, as the
inner loop uses them."""

OBSERVER_UNSTARTED: ObserverState = (math.nan, math.nan, 0.0, 0.0, 0.0, 0.0)


def momentum(q2: float, w1: float, w2: float, p: LimbParams) -> tuple[float, float]:
    """P = M(theta) omega with M = [[M11, -M12], [-M12, M22]]."""
    m11, m12, m22 = mass_matrix(q2, p)
    return m11 * w1 - m12 * w2, -m12 * w1 + m22 * w2


def model_torque(m: tuple[float, float, float, float, float, float, float, float], p: LimbParams
                 ) -> tuple[float, float]:
    """F = Mdot omega + tau + N of the nominal model at measurement m (dP/dt = F + d)."""
    q1, q2, w1, w2, z1, z2 = m[0], m[1], m[2], m[3], m[4], m[5]
    _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
    n1, n2 = n_terms(q1, q2, w1, w2, p)
    bs = p.b_coupling * math.sin(q2)
    f1 = -p.k1 * z1 * a1 + n1 + bs * w2 * (w2 - 2.0 * w1)   # (dM/dt) omega: dM11/dt = -2 b sin(q2) w2,
    f2 = -p.k2 * z2 * a2 + n2 + bs * w2 * w1                # dM12/dt = -b sin(q2) w2
    return f1, f2


def observer_step(m: tuple[float, float, float, float, float, float, float, float], obs: ObserverState,
                  p: LimbParams, bandwidth_rad_s: float, dt_s: float) -> tuple[ObserverState, Estimate]:
    """Third-order extended-state momentum observer (d and its rate as states), all three poles at -w0:
    e = P - xi, xi' = F + d_hat + 3 w0 e, d_hat' = d_rate + 3 w0^2 e, d_rate' = w0^3 e, so that
    d_hat / d = (3 w0^2 s + w0^3) / (s + w0)^3: no lag for a ramp, an error ~ 3 (omega / w0)^2 for a sine.
    Forward Euler over dt_s. Returns (the state for the next measurement, the estimate for this one): the estimate
    is the one predicted for this measurement's time, not the updated one, which belongs to t + dt_s (applying that
    one a period early is what limited the 2 Hz case, docs/deviations.md section 10). The first call starts xi at
    the measured momentum (d_hat = 0)."""
    p1, p2 = momentum(m[1], m[2], m[3], p)
    xi1, xi2, d1, d2, r1, r2 = obs
    if xi1 != xi1:  # NaN: not started
        xi1, xi2 = p1, p2
    e1, e2 = p1 - xi1, p2 - xi2
    l1, l2, l3 = 3.0 * bandwidth_rad_s, 3.0 * bandwidth_rad_s * bandwidth_rad_s, bandwidth_rad_s ** 3
    f1, f2 = model_torque(m, p)
    new = (xi1 + dt_s * (f1 + d1 + l1 * e1), xi2 + dt_s * (f2 + d2 + l1 * e2),
           d1 + dt_s * (r1 + l2 * e1), d2 + dt_s * (r2 + l2 * e2), r1 + dt_s * l3 * e1, r2 + dt_s * l3 * e2)
    return new, (d1, d2, r1, r2)

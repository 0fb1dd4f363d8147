"""One 1 kHz sample of the offline session: the edge's inner step on the DBC-quantised feedback, the VOLTAGE_CMD
frame's quantisation and the drive's saturation, and one driver period of the plant (`DriverCore.step`'s RK4
sub-steps on `rk4_core`, its soft-limit check `limit_bits`). Plain float code: `make_session_steps` is the kernel of
the offline session engine (between the samples at which the edge's and the controller's cores act) and of
`simulate`, compiled by numba (sea_hil/jit.py) or run as plain Python."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sea_hil.controller.inner import inner_step
from sea_hil.dynamics import State, deflections, is_finite, rk4_core, saturate
from sea_hil.offline.wire_quantiser import quantised
from sea_hil.plant_emulator.soft_limits import limit_bits


def feedback_measurement(x: State, p: Any, lsb: tuple[float, float, float, float, float]
                         ) -> tuple[float, float, float, float, float, float, float, float]:
    """(theta1, theta2, omega1, omega2, delta1, delta2, nut_vel1, nut_vel2) of the driver's feedback frames as the
    edge decodes them (DBC resolution; in range). Plain float code: the kernel compiles it."""
    dl1, dl2, _, _ = deflections(x, p)
    return quantised_feedback(x, dl1, dl2, lsb)


def quantised_feedback(x: State, dl1: float, dl2: float, lsb: tuple[float, float, float, float, float]
                       ) -> tuple[float, float, float, float, float, float, float, float]:
    """`feedback_measurement` of x whose spring deflections (`deflections`) are dl1, dl2: the kernel computes them
    once per sample, for the drive's soft-limit check and for the feedback."""
    return (quantised(x[0], lsb[0]), quantised(x[1], lsb[0]), quantised(x[2], lsb[1]), quantised(x[3], lsb[1]),
            quantised(dl1, lsb[2]), quantised(dl2, lsb[2]), quantised(x[6], lsb[3]), quantised(x[7], lsb[3]))


def edge_drive_sample(x, m, k, period_ns, substeps, vx, s, hold_measured, p, pn, gains, obs, dt_s,
                      limit_v, dist_tab, lsb, lim, faulted):
    """Sample k from the plant state x and its decoded feedback m: the edge's inner step on its nominal model pn
    (`inner_step`: disturbance observer state obs, backstepping voltage) -> quantised, saturated VOLTAGE_CMD -> one
    driver period of the plant p (0 V once `faulted`: the `ErrorFlags` bits of the drive soft limits of `lim`, a
    `DriveLimits`, the plant left, checked on every integrated sample with `DriverCore`'s own `limit_bits`; 0: none).
    Returns (x, m of the new x, saturated, u1, u2 commanded, obs, faulted, finite); not finite: x diverged (m is
    then the old one)."""
    u1, u2, saturated, obs = inner_step(m, vx, s, hold_measured, obs, pn, gains, limit_v, dt_s)
    u1 = saturate(quantised(u1, lsb[4]), p.voltage_limit)     # the drive's own limit
    u2 = saturate(quantised(u2, lsb[4]), p.voltage_limit)
    c1, c2 = u1, u2
    if faulted:             # the drive ignores commands in FAULT: 0 V
        u1 = 0.0
        u2 = 0.0
    t = k * period_ns * 1e-9
    h = (period_ns * 1e-9) / substeps
    for i in range(substeps):
        d = dist_tab[k * substeps + i]
        x = rk4_core(t + i * h, x, (u1, u2), h, p, (d[0], d[1]), (d[2], d[3]), (d[4], d[5]))
    if not is_finite(x):
        return x, m, saturated, c1, c2, obs, faulted, False
    d1, d2, _, _ = deflections(x, p)      # once: the soft-limit check and the feedback frames
    if not faulted:         # `DriverCore`'s soft-limit check on the new sample
        faulted = limit_bits(lim, (x[0], x[1]), (x[2], x[3]), (d1, d2), p.k1, p.k2)
    return x, quantised_feedback(x, d1, d2, lsb), saturated, c1, c2, obs, faulted, True


def make_session_steps(fingerprint: str = "") -> Callable[..., tuple]:
    """The per-run kernel; `fingerprint` (see sea_hil/jit.py) only keys numba's disk cache."""

    def session_steps(x, k0, n_steps, period_ns, substeps, vx, s, hold_measured, p, pn, gains, obs, dt_s,
                      limit_v, dist_tab, lsb, lim, faulted):
        """Samples k0 .. k0 + n_steps - 1 (`edge_drive_sample`) from the state x of sample k0. Returns (x, m of the
        new x, saturated steps, max |u1|, max |u2| commanded, first non-finite sample or -1, obs, faulted: the latched
        limit bits)."""
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        sat_count = 0
        u1_max = 0.0
        u2_max = 0.0
        m = feedback_measurement(x, p, lsb)
        for k in range(k0, k0 + n_steps):
            x, m, saturated, u1, u2, obs, faulted, ok = edge_drive_sample(
                x, m, k, period_ns, substeps, vx, s, hold_measured, p, pn, gains, obs, dt_s, limit_v, dist_tab, lsb,
                lim, faulted)
            if saturated:
                sat_count += 1
            u1_max = max(u1_max, abs(u1))
            u2_max = max(u2_max, abs(u2))
            if not ok:
                return x, m, sat_count, u1_max, u2_max, k, obs, faulted
        return x, m, sat_count, u1_max, u2_max, -1, obs, faulted

    return session_steps

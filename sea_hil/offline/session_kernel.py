"""The whole offline session in one compiled call: the sample loop of `sea_hil.offline.session_loop.SessionLoop` for
the paper's scheme (trigger at the controller, no delay compensation: the sweep's default), with the controller's
outer loop inside the kernel.

Per 1 kHz sample k, in the loop's order: the edge publishes the feedback every outer sample into the uplink; the
controller handles the states released by now (newest only; lead-in, trigger Eq. 16-19, SMC Eq. 12-13, the edge's
envelope, the downlink); the edge applies the setpoints released by now; then `edge_drive_sample` (inner step +
driver period). Everything numeric is the live code, compiled (sea_hil/jit.py registers every project function it
calls): `tracking_error`, `epsilon`, `event_reason`, `smc_law`, `gait_sample`, `quintic` / `lead_in_sample`,
`admissible`, `edge_drive_sample`. The links come in as per-message delivery offsets drawn beforehand from the
session's own `LinkEmulator` streams (`sea_hil.offline.session_fast.delivery_offsets`); `_deliver` applies the
emulator's FIFO rule to them in simulated time. What the recorder would see is written into preallocated arrays
(`Records`), turned into the session's messages afterwards. `tests/test_session_kernel.py` checks every message and
count against the Python loop.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from sea_hil.controller.envelope import admissible
from sea_hil.controller.smc import smc_law, tracking_error
from sea_hil.controller.trajectory import gait_sample, lead_in_sample, quintic
from sea_hil.controller.trigger import NO_EVENT, epsilon, event_reason
from sea_hil.offline.drive_kernel import edge_drive_sample, feedback_measurement
from sea_hil.protocol.payloads import TriggerReason

TIME = int(TriggerReason.TIME)
# how the kernel ended
CYCLES_DONE = 0       # the controller handled its first state after the measured cycles
SAMPLES_DONE = 1      # n_max samples simulated
DIVERGED = 2          # the plant state is not finite (at sample k)
BAD_SETPOINT = 3      # the SMC gave a non-finite setpoint (the last setpoint record; its payload is invalid)


class Drive(NamedTuple):
    x0: tuple                # the plant state at sample 0
    p: Any                   # the plant (LimbParams)
    lsb: tuple               # DBC resolutions (wire_quantiser.dbc_resolutions)
    limits: tuple            # drive soft limits (see edge_drive_sample)
    period_ns: int
    substeps: int
    dist_tab: np.ndarray     # driver_disturbance_table
    n_max: int               # samples at most
    outer_every: int         # samples per outer sample (the edge publishes then)


class Edge(NamedTuple):
    pn: Any                  # the nominal model
    gains: Any               # InnerGains
    obs0: tuple              # observer state at start
    dt_s: float
    limit_v: float
    envelope_m: tuple        # the setpoint envelope (deflection_max_m)
    max_answer_age_ns: int   # a setpoint answering a state sampled longer ago is dropped (0: off)


class Controller(NamedTuple):
    et: bool                 # event-triggered (else every state is answered)
    threshold: float         # Eq. 19
    r: float
    max_inter_event_ns: int
    params: Any              # the controller's nominal model
    c: float
    rho: float
    boundary_layer: float
    rate_rad_s: float        # the gait's base angular rate
    lead_in_ns: int
    duration_ns: int


class Links(NamedTuple):
    up_offset_ns: np.ndarray     # per state published: delivery - publish time, -1 = lost
    up_fifo: bool
    down_offset_ns: np.ndarray   # per setpoint admitted by the envelope
    down_fifo: bool


class Records(NamedTuple):
    """Preallocated outputs (n = states the edge can publish); filled up to the counts the kernel returns."""
    pub_ns: np.ndarray       # (n,) sample time of published state i (seq i + 1)
    pub_fb: np.ndarray       # (n, 8) its feedback
    up_at: np.ndarray        # (n,) delivery time, -1 lost
    up_done: np.ndarray      # (n,) bool: delivered to the controller, or lost
    recv: np.ndarray         # (n, 2) states the controller took: published index, time
    sp_i: np.ndarray         # (n, 3) setpoints: sent time, state seq, reason
    sp_f: np.ndarray         # (n, 4) v_x1, v_x2, s1, s2
    down_at: np.ndarray      # (n,) delivery time, -1 lost or rejected
    down_done: np.ndarray    # (n,) bool
    tr_i: np.ndarray         # (n, 4) tracking: controller time, state seq, reason or NO_EVENT, setpoint seq or 0
    tr_f: np.ndarray         # (n, 4) theta1, theta2, theta1_d, theta2_d
    rejected: np.ndarray     # (n,) setpoint indices the envelope rejected


def new_records(n: int) -> Records:
    i64, f64 = np.int64, np.float64
    return Records(np.zeros(n, i64), np.zeros((n, 8), f64), np.full(n, -1, i64), np.zeros(n, np.bool_),
                   np.zeros((n, 2), i64), np.zeros((n, 3), i64), np.zeros((n, 4), f64), np.full(n, -1, i64),
                   np.zeros(n, np.bool_), np.zeros((n, 4), i64), np.zeros((n, 4), f64), np.zeros(n, i64))


def _deliver(offset_ns: int, now_ns: int, fifo: bool, last_ns: int) -> tuple[int, int]:
    """(delivery time or -1 if lost, the new last delivery) of a message sent now: `LinkEmulator.submit`'s FIFO rule
    (`reorder = False`) on a drawn offset; last_ns -1 = nothing delivered yet."""
    if offset_ns < 0:
        return -1, last_ns
    at = now_ns + offset_ns
    if fifo and last_ns >= 0:
        at = max(at, last_ns)
    return at, (at if last_ns < 0 else max(at, last_ns))


def _pop_due(at: np.ndarray, done: np.ndarray, lo: int, hi: int, now_ns: int) -> int:
    """Index of the next message in [lo, hi) released by now (earliest delivery, ties in send order) or -1: the
    order of `DelayQueue.pop_due`."""
    best = -1
    for i in range(lo, hi):
        if not done[i] and at[i] <= now_ns and (best < 0 or at[i] < at[best]):
            best = i
    return best


def _first_open(done: np.ndarray, lo: int, hi: int) -> int:
    while lo < hi and done[lo]:
        lo += 1
    return lo


def make_session_kernel(fingerprint: str = "") -> Callable[..., tuple]:
    """The whole-session kernel; `fingerprint` (see sea_hil/jit.py) only keys numba's disk cache."""

    def session_kernel(dr, ed, ct, ln, rec):
        """Runs the session; returns (end status, samples k, states taken, setpoints, tracking records, rejected,
        saturated steps, max |u1|, max |u2| commanded, faulted)."""
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        x = dr.x0
        m = feedback_measurement(x, dr.p, dr.lsb)
        obs, vx, s, hold_measured, faulted = ed.obs0, (0.0, 0.0), (0.0, 0.0), True, False
        sat, u1_max, u2_max = 0, 0.0, 0.0
        n_pub = up_lo = n_recv = n_sp = down_lo = n_down = n_tr = n_rej = newest = 0
        up_last = down_last = -1
        t0_ns, started = 0, False
        c_hip = c_knee = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        eps_i: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        trig_started, t_i_ns = False, 0
        status, k = SAMPLES_DONE, 0
        while k < dr.n_max:
            now = k * dr.period_ns
            if k % dr.outer_every == 0:             # the edge publishes state seq n_pub + 1
                rec.pub_ns[n_pub] = now
                for q in range(8):
                    rec.pub_fb[n_pub, q] = m[q]
                at, up_last = _deliver(ln.up_offset_ns[n_pub], now, ln.up_fifo, up_last)
                rec.up_at[n_pub] = at
                rec.up_done[n_pub] = at < 0
                n_pub += 1
            while status == SAMPLES_DONE:           # the controller: states released by now
                i = _pop_due(rec.up_at, rec.up_done, up_lo, n_pub, now)
                if i < 0:
                    break
                rec.up_done[i] = True
                up_lo = _first_open(rec.up_done, up_lo, n_pub)
                if i + 1 <= newest:                 # released after a newer one: ignored
                    continue
                newest = i + 1
                rec.recv[n_recv, 0], rec.recv[n_recv, 1] = i, now
                n_recv += 1
                theta = (rec.pub_fb[i, 0], rec.pub_fb[i, 1])
                omega = (rec.pub_fb[i, 2], rec.pub_fb[i, 3])
                if not started:
                    started, t0_ns = True, rec.pub_ns[i] + ct.lead_in_ns
                    if ct.lead_in_ns:
                        g = gait_sample(ct.rate_rad_s, 0.0)
                        dur = ct.lead_in_ns * 1e-9
                        c_hip = quintic(theta[0], omega[0], 0.0, g[0][0], g[1][0], g[2][0], dur)
                        c_knee = quintic(theta[1], omega[1], 0.0, g[0][1], g[1][1], g[2][1], dur)
                t_ns = rec.pub_ns[i] - t0_ns
                if t_ns > ct.duration_ns:
                    status = CYCLES_DONE
                    break
                if t_ns < 0 and ct.lead_in_ns:
                    ds = lead_in_sample(c_hip, c_knee, ct.lead_in_ns * 1e-9, t_ns * 1e-9)
                else:
                    ds = gait_sample(ct.rate_rad_s, t_ns * 1e-9)
                eps = epsilon(tracking_error(theta, omega, ds[0], ds[1]), ds[0], ds[1])
                code = TIME
                if ct.et:
                    code = event_reason(trig_started, eps_i, t_i_ns, t_ns, eps, ct.threshold, ct.r,
                                        ct.max_inter_event_ns)
                    if code != NO_EVENT:
                        trig_started, eps_i, t_i_ns = True, eps, t_ns
                if code != NO_EVENT:
                    v, sl = smc_law(theta, omega, ds[0], ds[1], ds[2], ct.params, ct.c, ct.rho, ct.boundary_layer)
                    rec.sp_i[n_sp, 0], rec.sp_i[n_sp, 1], rec.sp_i[n_sp, 2] = now, i + 1, code
                    rec.sp_f[n_sp, 0], rec.sp_f[n_sp, 1], rec.sp_f[n_sp, 2], rec.sp_f[n_sp, 3] = v[0], v[1], sl[0], sl[1]
                    n_sp += 1
                    if not (math.isfinite(v[0]) and math.isfinite(v[1]) and math.isfinite(sl[0])
                            and math.isfinite(sl[1])):
                        return BAD_SETPOINT, k, n_recv, n_sp, n_tr, n_rej, sat, u1_max, u2_max, faulted
                    if admissible(v, ed.envelope_m):
                        at, down_last = _deliver(ln.down_offset_ns[n_down], now, ln.down_fifo, down_last)
                        rec.down_at[n_sp - 1] = at
                        n_down += 1
                    else:
                        rec.rejected[n_rej] = n_sp - 1
                        n_rej += 1
                    rec.down_done[n_sp - 1] = rec.down_at[n_sp - 1] < 0
                rec.tr_i[n_tr, 0], rec.tr_i[n_tr, 1], rec.tr_i[n_tr, 2] = t_ns, i + 1, code
                rec.tr_i[n_tr, 3] = n_sp if code != NO_EVENT else 0
                rec.tr_f[n_tr, 0], rec.tr_f[n_tr, 1], rec.tr_f[n_tr, 2], rec.tr_f[n_tr, 3] = \
                    theta[0], theta[1], ds[0][0], ds[0][1]
                n_tr += 1
            if status == CYCLES_DONE:
                break
            while True:                             # the edge: setpoints released by now
                j = _pop_due(rec.down_at, rec.down_done, down_lo, n_sp, now)
                if j < 0:
                    break
                rec.down_done[j] = True
                down_lo = _first_open(rec.down_done, down_lo, n_sp)
                if ed.max_answer_age_ns and now - rec.pub_ns[rec.sp_i[j, 1] - 1] > ed.max_answer_age_ns:
                    continue                        # a late answer: dropped, as the live edge does
                vx, s, hold_measured = (rec.sp_f[j, 0], rec.sp_f[j, 1]), (rec.sp_f[j, 2], rec.sp_f[j, 3]), False
            x, m, saturated, u1, u2, obs, faulted, ok = edge_drive_sample(
                x, m, k, dr.period_ns, dr.substeps, vx, s, hold_measured, dr.p, ed.pn, ed.gains, obs, ed.dt_s,
                ed.limit_v, dr.dist_tab, dr.lsb, dr.limits, faulted)
            if saturated:
                sat += 1
            u1_max = max(u1_max, abs(u1))
            u2_max = max(u2_max, abs(u2))
            if not ok:
                return DIVERGED, k, n_recv, n_sp, n_tr, n_rej, sat, u1_max, u2_max, faulted
            k += 1
        return status, k, n_recv, n_sp, n_tr, n_rej, sat, u1_max, u2_max, faulted

    return session_kernel

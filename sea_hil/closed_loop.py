"""Offline closed loop (no network): plant model + outer ET/TT SMC + 1 kHz backstepping inner loop, in one process.

The split mirrors the networked session: the inner loop only sees the 1 kHz measurement and the latest setpoint, the
outer loop samples every `sample_period_s` and transmits a setpoint only on events.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.inner import InnerLoop
from controller.outer import OuterController
from controller.smc import JointState
from controller.trajectory import make_trajectory
from plant_emulator.dynamics import deflections, initial_state, is_finite
from plant_emulator.disturbance import make_disturbance
from plant_emulator.integrator import advance
from protocol.config import SeaHilConfig
from protocol.errors import SeaHilError
from protocol.mechanics import limb_params


@dataclass
class SimResult:
    mode: str
    duration_s: float
    t_s: np.ndarray            # outer sample times
    theta_rad: np.ndarray      # (n, 2) measured at outer samples
    desired_rad: np.ndarray    # (n, 2)
    voltage_v: np.ndarray      # (n_inner, 2) applied voltages
    event_t_s: np.ndarray      # times of transmitted setpoints
    event_reason: np.ndarray   # TriggerReason values
    saturated_steps: int


def inner_ratio(cfg: SeaHilConfig) -> int:
    ratio = cfg.controller.sample_period_s * cfg.controller.inner_rate_hz
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise SeaHilError("controller.sample_period_s must be a whole number of inner-loop periods")
    return int(round(ratio))


def simulate(cfg: SeaHilConfig, mode: str, cycles: int | None = None) -> SimResult:
    p = limb_params(cfg.plant)
    traj = make_trajectory(cfg.trajectory)
    dist = make_disturbance(cfg.disturbance)
    ratio = inner_ratio(cfg)
    dt = 1.0 / cfg.controller.inner_rate_hz
    dt_ns = int(round(dt * 1e9))
    duration_s = traj.period_s * (cycles if cycles is not None else cfg.sim.cycles)
    n_inner = int(round(duration_s / dt))
    n_outer = (n_inner + ratio - 1) // ratio
    d0 = traj.sample(0.0)
    x = initial_state(d0.theta_rad[0], d0.theta_rad[1], d0.omega_rad_s[0], d0.omega_rad_s[1], p)
    outer = OuterController(cfg, p, mode)
    inner = InnerLoop(cfg, p, d0.theta_rad)
    substeps = cfg.sim.substeps
    t_out = np.empty(n_outer)
    theta = np.empty((n_outer, 2))
    desired = np.empty((n_outer, 2))
    volts = np.empty((n_inner, 2))
    ev_t: list[float] = []
    ev_r: list[int] = []
    j = 0
    for k in range(n_inner):
        t = k * dt
        dl1, dl2, _, _ = deflections(x, p)
        meas = (x[0], x[1], x[2], x[3], dl1, dl2, x[6], x[7])
        if k % ratio == 0:
            ds = traj.sample(t)
            sp = outer.step(k * dt_ns, j, JointState((x[0], x[1]), (x[2], x[3])), ds)
            if sp is not None:
                inner.hold(sp.deflection_m, sp.sliding)
                ev_t.append(t)
                ev_r.append(int(sp.reason))
            t_out[j] = t
            theta[j] = (x[0], x[1])
            desired[j] = ds.theta_rad
            j += 1
        u = inner.voltage(meas)
        volts[k] = u
        x = advance(t, x, u, dt, substeps, p, dist)
        if not is_finite(x):
            raise SeaHilError(f"simulation diverged at t = {t:.3f} s")
    return SimResult(mode, duration_s, t_out[:j], theta[:j], desired[:j], volts, np.array(ev_t),
                     np.array(ev_r, dtype=int), inner.saturated_steps)

"""Offline closed loop (no network): plant model + outer ET/TT SMC + 1 kHz backstepping inner loop, in one process.

The split mirrors the networked session: the inner loop only sees the 1 kHz measurement and the latest setpoint, the
outer loop samples every `sample_period_s` and transmits a setpoint only on events.

Speed: the outer loop (trajectory, trigger, SMC: 100 Hz) runs in Python; the inner steps between two outer samples
(the edge's backstepping voltage + the driver's RK4 sub-steps, with the one disturbance table of the driver) run in
the offline session engine's kernel (`sea_hil.offline.drive_kernel.session_steps`, no drive limits, exact or
DBC-quantised feedback), compiled with numba when it is installed (sea_hil/jit.py), else as plain Python.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.outer import OuterController
from sea_hil.controller.smc import JointState
from sea_hil.controller.trajectory import make_trajectory
from sea_hil.dynamics import State, initial_state
from sea_hil.errors import SeaHilError
from sea_hil.jit import compiled, entry
from sea_hil.mechanics import limb_params
from sea_hil.offline.drive_kernel import make_session_steps
from sea_hil.offline.wire_quantiser import EXACT, dbc_resolutions, quantised
from sea_hil.plant_emulator.disturbance import DisturbanceTable
from sea_hil.plant_emulator.soft_limits import DriveLimits


@dataclass
class SimResult:
    mode: str
    duration_s: float
    t_s: np.ndarray            # outer sample times
    theta_rad: np.ndarray      # (n, 2) measured at outer samples
    desired_rad: np.ndarray    # (n, 2)
    max_abs_voltage_v: tuple[float, float]   # the largest |voltage| commanded per motor
    inner_steps: int           # inner (feedback) samples simulated
    event_t_s: np.ndarray      # times of transmitted setpoints
    event_reason: np.ndarray   # TriggerReason values
    saturated_steps: int


def inner_ratio(cfg: SeaHilConfig) -> int:
    """Inner steps per outer sample (a whole number >= 1: checked when the config is loaded)."""
    return int(round(cfg.controller.sample_period_s * cfg.can.feedback_rate_hz))


def simulate(cfg: SeaHilConfig, mode: str, cycles: int | None = None, jit: bool = True, quantise: bool = False
             ) -> SimResult:
    """Closed loop over `cycles` trajectory periods; jit=False runs `inner_steps` as plain Python (the reference).
    quantise=True rounds every measurement and voltage to its CAN frame's resolution, as the networked path does."""
    p = limb_params(cfg.plant)
    pn = nominal_params(cfg)
    traj = make_trajectory(cfg.trajectory)
    ratio = inner_ratio(cfg)
    dt = 1.0 / cfg.can.feedback_rate_hz
    dt_ns = int(round(dt * 1e9))
    duration_s = traj.period_s * (cycles if cycles is not None else cfg.sim.cycles)
    n_inner = int(round(duration_s / dt))
    n_outer = (n_inner + ratio - 1) // ratio
    substeps = cfg.sim.substeps
    d0 = traj.sample(0.0)
    x: State = initial_state(d0.theta_rad[0], d0.theta_rad[1], d0.omega_rad_s[0], d0.omega_rad_s[1], p)
    outer = OuterController(cfg, pn, mode)
    inner = InnerLoop(cfg, pn, d0.theta_rad, dt)
    dist_tab = DisturbanceTable(cfg.disturbance, dt_ns, substeps).upto(n_inner)
    lsb = dbc_resolutions() if quantise else EXACT
    kernel = compiled(make_session_steps) if jit else None
    steps = kernel if kernel is not None else make_session_steps()
    tab = dist_tab if kernel is not None else dist_tab.tolist()  # plain floats for the Python path
    no_limits = DriveLimits()       # the closed loop has no drive soft limits
    u_max = (0.0, 0.0)
    call: Any = None
    theta: list[tuple[float, float]] = []
    desired: list[tuple[float, float]] = []
    ev_t: list[float] = []
    ev_r: list[int] = []
    for j in range(n_outer):
        k0 = j * ratio
        t = k0 * dt
        ds = traj.sample(t)
        seen = JointState((quantised(x[0], lsb[0]), quantised(x[1], lsb[0])),
                          (quantised(x[2], lsb[1]), quantised(x[3], lsb[1])))
        sp = outer.step(k0 * dt_ns, j, seen, ds)
        if sp is not None:
            inner.hold(sp.deflection_m, sp.sliding)
            ev_t.append(t)
            ev_r.append(int(sp.reason))
        theta.append((x[0], x[1]))
        desired.append(ds.theta_rad)
        held = inner.deflection_m
        args = (x, k0, min(ratio, n_inner - k0), dt_ns, substeps, held or (0.0, 0.0), inner.sliding, held is None, p,
                pn, inner.gains, inner.observer, dt, pn.voltage_limit, tab, lsb, no_limits, 0)
        call = entry(steps, args) if call is None else call   # the types stay these (`sea_hil.jit.entry`)
        x, _, n_sat, u1, u2, bad_k, inner.observer, _ = call(*args)
        inner.saturated_steps += n_sat
        u_max = (max(u_max[0], u1), max(u_max[1], u2))
        if bad_k >= 0:
            raise SeaHilError(f"simulation diverged at t = {bad_k * dt:.3f} s")
    t_out = np.arange(n_outer) * ratio * dt  # = k0 * dt of each sample
    return SimResult(mode, duration_s, t_out, np.array(theta).reshape(-1, 2), np.array(desired).reshape(-1, 2),
                     u_max, n_inner, np.array(ev_t), np.array(ev_r, dtype=int), inner.saturated_steps)

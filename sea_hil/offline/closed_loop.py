"""Offline closed loop (no network): plant model + outer ET/TT SMC + 1 kHz backstepping inner loop, in one process.

The split mirrors the networked session: the inner loop only sees the 1 kHz measurement and the latest setpoint, the
outer loop samples every `sample_period_s` and transmits a setpoint only on events.

Speed: the outer loop (trajectory, trigger, SMC: 100 Hz) runs in Python; the inner steps between two outer samples
(backstepping voltage + RK4 sub-steps of the plant) run in `inner_steps`, which is compiled with numba when it is
installed (sea_hil/jit.py: the same source and callees, compiled, cached on disk), else as plain Python.
"""
from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sea_hil.config.model import DisturbanceConfig
from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.inner import InnerLoop, inner_step
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.observer import ObserverState
from sea_hil.controller.outer import OuterController
from sea_hil.controller.smc import JointState
from sea_hil.controller.trajectory import make_trajectory
from sea_hil.dynamics import State, deflections, initial_state, is_finite, rk4_core
from sea_hil.errors import SeaHilError
from sea_hil.jit import compiled
from sea_hil.mechanics import limb_params
from sea_hil.offline.wire_quantiser import EXACT, dbc_resolutions, quantised
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.integrator import Disturbance


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
    """Inner steps per outer sample (a whole number >= 1: checked when the config is loaded)."""
    return int(round(cfg.controller.sample_period_s * cfg.can.feedback_rate_hz))


def make_inner_steps(fingerprint: str = "") -> Callable[..., tuple[State, int, int, ObserverState]]:
    """The inner-step kernel; `fingerprint` (see sea_hil/jit.py) only keys numba's disk cache."""

    def inner_steps(x, k0, n_steps, dt, substeps, vx, s, hold_measured, p, pn, gains, obs, limit_v,
                    dist_tab, volts, lsb):
        """Inner steps k0 .. k0 + n_steps - 1: measurement of plant x (truth p) -> the edge's inner step on the
        nominal model pn (observer state obs, limited backstepping voltage written to volts[k]) -> `substeps` RK4
        sub-steps with the disturbance torques of dist_tab row k * substeps + i (d(t_i), d(t_i + h/2), d(t_i + h)).
        `lsb` = (theta, omega, delta, nut velocity, voltage) resolutions of the CAN frames
        (sea_hil/offline/wire_quantiser.py; zeros: exact values) rounds what the inner loop sees and sends.
        Returns (x, saturated step count, first step whose result is not finite or -1, observer state).
        Plain float code, untyped: this body is what numba compiles."""
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        h = dt / substeps
        saturated_count = 0
        for k in range(k0, k0 + n_steps):
            t = k * dt
            dl1, dl2, _, _ = deflections(x, p)
            m = (quantised(x[0], lsb[0]), quantised(x[1], lsb[0]), quantised(x[2], lsb[1]), quantised(x[3], lsb[1]),
                 quantised(dl1, lsb[2]), quantised(dl2, lsb[2]), quantised(x[6], lsb[3]), quantised(x[7], lsb[3]))
            u1, u2, saturated, obs = inner_step(m, vx, s, hold_measured, obs, pn, gains, limit_v, dt)
            u1, u2 = quantised(u1, lsb[4]), quantised(u2, lsb[4])
            if saturated:
                saturated_count += 1
            volts[k, 0] = u1
            volts[k, 1] = u2
            for i in range(substeps):
                d = dist_tab[k * substeps + i]
                x = rk4_core(t + i * h, x, (u1, u2), h, p, (d[0], d[1]), (d[2], d[3]), (d[4], d[5]))
            if not is_finite(x):
                return x, saturated_count, k, obs
        return x, saturated_count, -1, obs

    return inner_steps


def disturbance_table(dist: Disturbance, cfg: DisturbanceConfig, n_inner: int, dt: float, substeps: int
                      ) -> np.ndarray:
    """(n_inner * substeps, 6): d(t_i), d(t_i + h/2), d(t_i + h) of every RK4 sub-step, at exactly the times
    `integrator.advance(k dt, ...)` samples. All zero without calls when the config has no disturbance (every kind is
    bounded by |amplitude_nm|)."""
    if cfg.is_zero():
        return np.zeros((n_inner * substeps, 6))
    h = dt / substeps
    t_i = (np.arange(n_inner) * dt)[:, None] + np.arange(substeps) * h   # same float ops as advance/rk4_step
    times = np.stack([t_i, t_i + 0.5 * h, t_i + h], axis=-1).ravel().tolist()
    values = np.fromiter(itertools.chain.from_iterable(map(dist, times)), dtype=float, count=2 * len(times))
    return values.reshape(n_inner * substeps, 6)


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
    dist_tab = disturbance_table(make_disturbance(cfg.disturbance), cfg.disturbance, n_inner, dt, substeps)
    lsb = dbc_resolutions() if quantise else EXACT
    kernel = compiled(make_inner_steps) if jit else None
    steps = kernel if kernel is not None else make_inner_steps()
    tab = dist_tab if kernel is not None else dist_tab.tolist()  # plain floats for the Python path
    theta: list[tuple[float, float]] = []
    desired: list[tuple[float, float]] = []
    volts = np.empty((n_inner, 2))
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
        x, n_sat, bad_k, inner.observer = steps(x, k0, min(ratio, n_inner - k0), dt, substeps, held or (0.0, 0.0),
                                                inner.sliding, held is None, p, pn, inner.gains, inner.observer,
                                                pn.voltage_limit, tab, volts, lsb)
        inner.saturated_steps += n_sat
        if bad_k >= 0:
            raise SeaHilError(f"simulation diverged at t = {bad_k * dt:.3f} s")
    t_out = np.arange(n_outer) * ratio * dt  # = k0 * dt of each sample
    return SimResult(mode, duration_s, t_out, np.array(theta).reshape(-1, 2), np.array(desired).reshape(-1, 2),
                     volts, np.array(ev_t), np.array(ev_r, dtype=int), inner.saturated_steps)

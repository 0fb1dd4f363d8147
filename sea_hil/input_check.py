"""Inputs checked before anything moves (docs/verdict.md, "Inputs checked at load"): a config whose start pose or
trajectory the drive would refuse is an error at load, one line naming the key, the joint, the value and the limit,
instead of a session that faults the drive in its first 0.1 s and reports tracking figures of a limb that never moved.

Checked (`problems`): the start pose (`plant.initial_theta_rad`) inside the drive's soft position limits
(`[safety.drive]`) and the end stops (`[plant.end_stops]`); the trajectory (gait or CSV) over its cycle -- later
cycles repeat it (the gait, a periodic CSV) or hold its last sample (any other CSV) -- and the lead-in from the start
pose onto it (as the controller plans it, `controller/trajectory.py`), inside the soft position and velocity limits
and the end stops; the trajectory's feed-forward spring deflection (the SMC law, Eq. 13, on perfect tracking, with the
nominal model) inside the setpoint envelope (`[safety.setpoint]`) and the drive's spring-force limit; CSV sample
times strictly increasing and starting at t = 0 (the cycle is [0, last time]); link traces readable, and periods
consistent: the answer deadline `safety.setpoint.max_answer_age_s` above the links' fixed delay, the trigger's
`max_inter_event_s` at least one sample, the trajectory period at least two. A mechanism that is off
(`enabled = false`) is not checked.

`enforce` raises the first problem as a ConfigError (the CLI prints it and exits 2) unless `[verdict] check_inputs`
is false or the caller forces past it (`--allow-unsafe-start`); `sea-hil check` prints every problem. Who checks:
`run`, `sweep` and `Session` (everything); `simulate` what its offline closed loop has (the end stops, the CSV, the
periods: it has no drive firmware and no edge); not the single-node commands (`plant`, `edge`, `controller`,
`record`): whoever starts the session decides.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.smc import smc_law
from sea_hil.controller.trajectory import CsvTrajectory, GaitTrajectory, LeadIn, lead_in_duration_s, make_trajectory
from sea_hil.errors import ConfigError, SeaHilError
from sea_hil.protocol.link_trace import load_trace

JOINTS = ("hip", "knee")
CHECK_STEP_S = 1e-3   # the trajectory is checked at the inner-loop rate's default period


class Problem(NamedTuple):
    """One input the session would not survive: the key, and the line that says why."""
    key: str
    message: str

    def __str__(self) -> str:
        return self.message


def _range(key: str, what: str, values: np.ndarray, lo: tuple[float, float], hi: tuple[float, float],
           lo_key: str, hi_key: str, unit: str, at: np.ndarray | None = None) -> Iterator[Problem]:
    """A Problem per joint whose `values` (n x 2) leave [lo, hi]; the first sample outside named (time `at`)."""
    for j in (0, 1):
        col = values[:, j]
        for bad, limit, side, lkey in ((col > hi[j], hi[j], "above", hi_key), (col < lo[j], lo[j], "below", lo_key)):
            if not bad.any():
                continue
            i = int(np.argmax(np.abs(col - limit) * bad))   # the worst sample
            when = "" if at is None else f" at t = {at[i]:.3f} s"
            yield Problem(key, f"{key}: {JOINTS[j]} {what} {col[i]:.4g} {unit}{when} is {side} {lkey}[{j}] = "
                               f"{limit:.4g} {unit}")
            break


def _start_pose(cfg: SeaHilConfig) -> Iterator[Problem]:
    q = np.array([cfg.plant.initial_theta_rad], dtype=float)
    drive, stops = cfg.safety.drive, cfg.plant.end_stops
    key = "plant.initial_theta_rad"
    if drive.enabled:
        yield from _range(key, "start angle", q, drive.position_min_rad, drive.position_max_rad,
                          "safety.drive.position_min_rad", "safety.drive.position_max_rad", "rad")
    if stops.enabled:
        yield from _range(key, "start angle", q, stops.min_rad, stops.max_rad, "plant.end_stops.min_rad",
                          "plant.end_stops.max_rad", "rad")


def _csv(cfg: SeaHilConfig, traj: CsvTrajectory) -> Iterator[Problem]:
    """The CSV's times start the cycle at 0 (the loader checked its columns, numbers and increasing times)."""
    if abs(traj.start_s) > 1e-9:
        yield Problem("trajectory.csv_path", f"trajectory.csv_path: {cfg.trajectory.csv_path}: the first sample is "
                                             f"at t = {traj.start_s:g} s; the cycle starts at t = 0 (the times must "
                                             f"cover [0, {traj.end_s:g}] s)")


Motion = tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _motion(cfg: SeaHilConfig, traj: GaitTrajectory | CsvTrajectory) -> Motion:
    """The desired motion the drive will be asked for along `traj` (the config's trajectory, made once): (key, t,
    theta, omega, alpha) of one cycle, then (t, theta, omega) of the lead-in from the start pose at rest (t < 0)."""
    tc = cfg.trajectory
    key = "trajectory.csv_path" if tc.kind == "csv" else "trajectory.period_s"
    t = np.arange(0.0, traj.period_s + CHECK_STEP_S / 2, CHECK_STEP_S)
    s = [traj.sample(float(v)) for v in t]
    theta = np.array([x.theta_rad for x in s])
    omega = np.array([x.omega_rad_s for x in s])
    alpha = np.array([x.alpha_rad_s2 for x in s])
    theta0 = tuple(cfg.plant.initial_theta_rad)
    duration_s = lead_in_duration_s(theta0, s[0], tc.lead_in_s, tc.lead_in_max_velocity_rad_s)   # type: ignore
    if duration_s > 0:
        lead = LeadIn(theta0, (0.0, 0.0), s[0], duration_s)   # type: ignore[arg-type]
        tl = np.arange(-duration_s, 0.0, CHECK_STEP_S)
        ls = [lead.sample(float(v)) for v in tl]
        lq = np.array([x.theta_rad for x in ls]).reshape(-1, 2)
        lw = np.array([x.omega_rad_s for x in ls]).reshape(-1, 2)
    else:
        tl, lq, lw = np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2))
    return key, t, theta, omega, alpha, tl, lq, lw


def _tag(message: str, what: str) -> str:
    """A range problem's joint, quantity and limit, whichever part of the motion it is of."""
    body = message.split(": ", 1)[1].replace(f" {what} ", " ")
    words = body.split()
    return f"{words[0]} {words[1]} {words[-5]}"   # joint, quantity, the limit's key


def _trajectory(cfg: SeaHilConfig, traj: GaitTrajectory | CsvTrajectory) -> Iterator[Problem]:
    key, t, theta, omega, alpha, tl, lq, lw = _motion(cfg, traj)
    drive, stops = cfg.safety.drive, cfg.plant.end_stops
    start_bad = any(True for _ in _start_pose(cfg))   # then the lead-in starts outside: said once, of the start
    said: set[str] = set()   # (joint, quantity, limit) of the trajectory: the lead-in ending on it is not said again
    for what, k, tt, q, w in (("trajectory", key, t, theta, omega),
                              ("lead-in", "trajectory.lead_in_s", tl, lq, lw)):
        if not len(tt) or (start_bad and what == "lead-in"):
            continue
        found: list[Problem] = []
        if drive.enabled:
            found += _range(k, f"{what} angle", q, drive.position_min_rad, drive.position_max_rad,
                            "safety.drive.position_min_rad", "safety.drive.position_max_rad", "rad", tt)
            vmax = drive.velocity_max_rad_s
            found += _range(k, f"{what} velocity", w, (-vmax[0], -vmax[1]), vmax,
                            "-safety.drive.velocity_max_rad_s", "safety.drive.velocity_max_rad_s", "rad/s", tt)
        if stops.enabled:
            found += _range(k, f"{what} angle", q, stops.min_rad, stops.max_rad, "plant.end_stops.min_rad",
                            "plant.end_stops.max_rad", "rad", tt)
        for prob in found:
            tag = _tag(prob.message, what)
            if tag not in said:
                said.add(tag)
                yield prob
    env = cfg.safety.setpoint
    if not (env.enabled or drive.enabled):
        return
    p, c = nominal_params(cfg), cfg.controller
    vx = np.array([smc_law(tuple(q), tuple(w), tuple(q), tuple(w), tuple(a), p, c.c, c.rho, c.boundary_layer)[0]
                   for q, w, a in zip(theta, omega, alpha, strict=True)])
    if env.enabled:
        dmax = env.deflection_max_m
        yield from _range(key, "feed-forward deflection v_x", vx, (-dmax[0], -dmax[1]), dmax,
                          "-safety.setpoint.deflection_max_m", "safety.setpoint.deflection_max_m", "m", t)
    if drive.enabled:
        force = vx * np.array([p.k1, p.k2])
        fmax = drive.spring_force_max_n
        yield from _range(key, "feed-forward spring force", force, (-fmax[0], -fmax[1]), fmax,
                          "-safety.drive.spring_force_max_n", "safety.drive.spring_force_max_n", "N", t)


def _links_and_periods(cfg: SeaHilConfig) -> Iterator[Problem]:
    link = cfg.link
    for name in ("uplink", "downlink"):
        d = getattr(link, name)
        if d.trace_path:
            try:
                load_trace(d.trace_path)
            except SeaHilError as err:
                yield Problem(f"link.{name}.trace_path", f"link.{name}.trace_path: {err}")
    fixed_s = link.uplink.delay_s + link.downlink.delay_s
    age = cfg.safety.setpoint.max_answer_age_s
    if age > 0 and fixed_s >= age:
        yield Problem("safety.setpoint.max_answer_age_s",
                      f"safety.setpoint.max_answer_age_s: {age:g} s is not above the links' fixed round trip "
                      f"link.uplink.delay_s + link.downlink.delay_s = {fixed_s:g} s: every setpoint would be late")
    sample_s = cfg.controller.sample_period_s
    if cfg.trigger.max_inter_event_s < sample_s:
        yield Problem("trigger.max_inter_event_s",
                      f"trigger.max_inter_event_s: {cfg.trigger.max_inter_event_s:g} s is below one sample "
                      f"controller.sample_period_s = {sample_s:g} s")
    if cfg.trajectory.kind == "gait" and cfg.trajectory.period_s < 2 * sample_s:
        yield Problem("trajectory.period_s", f"trajectory.period_s: {cfg.trajectory.period_s:g} s is shorter than "
                                             f"two samples of controller.sample_period_s = {sample_s:g} s")
    if cfg.can.watchdog_timeout_s * cfg.can.feedback_rate_hz < 2:
        yield Problem("can.watchdog_timeout_s", f"can.watchdog_timeout_s: {cfg.can.watchdog_timeout_s:g} s is shorter "
                                                f"than two feedback periods (can.feedback_rate_hz = "
                                                f"{cfg.can.feedback_rate_hz:g} Hz): the drive would trip at once")


def offline_view(cfg: SeaHilConfig) -> SeaHilConfig:
    """What the offline closed loop (`sea-hil simulate`) has of `cfg`'s limits: the plant's end stops, no drive
    firmware (soft limits) and no edge (setpoint envelope)."""
    safety = cfg.safety.model_copy(update={"drive": cfg.safety.drive.model_copy(update={"enabled": False}),
                                           "setpoint": cfg.safety.setpoint.model_copy(update={"enabled": False})})
    return cfg.model_copy(update={"safety": safety, "link": type(cfg.link)()})


def problems(cfg: SeaHilConfig, *, motion: bool = True, offline: bool = False) -> list[Problem]:
    """Every input problem of `cfg` (see the module docstring); [] when it passes. `motion=False`: only the start
    pose, the links and the periods (cheap: a sweep checks the motion once, the links of every point);
    `offline`: what the offline closed loop has (`offline_view`)."""
    cfg = offline_view(cfg) if offline else cfg
    out = list(_start_pose(cfg)) + list(_links_and_periods(cfg))
    if not motion:
        return out
    try:
        traj = make_trajectory(cfg.trajectory)   # the file read once, with the loader's own checks and words
        if isinstance(traj, CsvTrajectory):
            out += list(_csv(cfg, traj))
        out += list(_trajectory(cfg, traj))
    except SeaHilError as err:   # an unreadable trajectory: the loader's own line
        key = "trajectory.csv_path" if cfg.trajectory.kind == "csv" else "trajectory"
        out.append(Problem(key, f"{key}: {err}"))
    return out


def enforce(cfg: SeaHilConfig, *, force: bool = False, motion: bool = True, offline: bool = False,
            where: str = "") -> SeaHilConfig:
    """`cfg` when its inputs pass (or `[verdict] check_inputs` is false, or `force`), else ConfigError with the
    first problem and how to run it anyway (`where`: a prefix naming e.g. the sweep point)."""
    if force or not cfg.verdict.check_inputs:
        return cfg
    found = problems(cfg, motion=motion, offline=offline)
    if found:
        more = f" (and {len(found) - 1} more: sea-hil check)" if len(found) > 1 else ""
        raise ConfigError(f"{where}{found[0].message}{more}; --allow-unsafe-start (or [verdict] check_inputs = false) "
                          f"runs it anyway")
    return cfg

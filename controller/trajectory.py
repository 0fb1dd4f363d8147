"""Desired joint trajectories x_d(t) with first and second derivatives.

`GaitTrajectory`: a smooth periodic hip/knee swing built from two Fourier harmonics (the paper's reference [13]
profile is not available; see docs/deviations.md). `CsvTrajectory`: samples `t, theta1, theta2` (rad) from a CSV file
interpolated by a cubic spline (periodic if the first and last rows coincide, else not-a-knot); derivatives are the
spline's analytic derivatives. `LeadIn`: the quintic that takes a limb from the state it was measured in (a robot
boots at rest) onto a trajectory's start (position, velocity and acceleration continuous), run before the measured
cycles of a networked session (`trajectory.lead_in_s`, docs/deviations.md).
"""
from __future__ import annotations

import csv
import hashlib
import math
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from sea_hil.config.model import TrajectoryConfig
from sea_hil.errors import TrajectoryError

# (offset, [(amplitude, harmonic, phase)]) per joint, angles in rad
_HIP = (0.05, ((0.35, 1, 0.0), (0.05, 2, 0.0)))
_KNEE = (0.55, ((0.40, 1, -0.5 * math.pi - 0.5), (0.10, 2, 1.0)))


class DesiredSample(NamedTuple):
    """x_d, xdot_d, xddot_d of both joints at one time (a NamedTuple: sampled several times per outer sample, a third
    of a frozen dataclass's construction time)."""
    theta_rad: tuple[float, float]
    omega_rad_s: tuple[float, float]
    alpha_rad_s2: tuple[float, float]


def gait_joint(spec: tuple[Any, ...], w: float, t: float) -> tuple[float, float, float]:
    """(q, q', q'') of one joint's Fourier spec (`_HIP`, `_KNEE`) at t, base angular rate w (rad/s)."""
    offset, harmonics = spec
    q, qd, qdd = offset, 0.0, 0.0
    for amp, k, phase in harmonics:
        wk = k * w
        arg = wk * t + phase
        s, c = math.sin(arg), math.cos(arg)
        q += amp * s
        qd += amp * wk * c
        qdd -= amp * wk * wk * s
    return q, qd, qdd


def gait_sample(w: float, t_s: float) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
    """The gait's (theta, omega, alpha) pairs at t_s; plain float code (the offline session kernel compiles it)."""
    h, k = gait_joint(_HIP, w, t_s), gait_joint(_KNEE, w, t_s)
    return (h[0], k[0]), (h[1], k[1]), (h[2], k[2])


class GaitTrajectory:
    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.rate_rad_s = 2.0 * math.pi / period_s     # base angular rate of the gait's harmonics

    def sample(self, t_s: float) -> DesiredSample:
        return DesiredSample(*gait_sample(self.rate_rad_s, t_s))


class CsvTrajectory:
    def __init__(self, path: str | Path) -> None:
        from scipy.interpolate import CubicSpline  # 0.35 s to import: only when a CSV trajectory is used

        t, q = _read_csv(Path(path))
        periodic = bool(np.allclose(q[0], q[-1]))
        self._spline = CubicSpline(t, q, axis=0, bc_type="periodic" if periodic else "not-a-knot")
        self._d1 = self._spline.derivative(1)
        self._d2 = self._spline.derivative(2)
        self._t0, self._t1 = float(t[0]), float(t[-1])
        self.start_s, self.end_s = self._t0, self._t1     # the file's first and last sample times
        self.period_s = self._t1 - self._t0
        self._periodic = periodic

    def sample(self, t_s: float) -> DesiredSample:
        if self._periodic:
            t_s = self._t0 + (t_s - self._t0) % self.period_s
        else:
            t_s = min(max(t_s, self._t0), self._t1)
        q, qd, qdd = self._spline(t_s), self._d1(t_s), self._d2(t_s)
        return DesiredSample((float(q[0]), float(q[1])), (float(qd[0]), float(qd[1])), (float(qdd[0]), float(qdd[1])))


def quintic(q0: float, v0: float, a0: float, q1: float, v1: float, a1: float, duration_s: float
            ) -> tuple[float, float, float, float, float, float]:
    """Coefficients c0..c5 of q(tau) = sum c_i tau^i on [0, T] with q, q', q'' = (q0, v0, a0) at 0 and (q1, v1, a1)
    at T."""
    T = duration_s
    h = q1 - q0 - v0 * T - 0.5 * a0 * T * T
    dv = v1 - v0 - a0 * T
    da = a1 - a0
    # float exponents: C pow() as Python's float ** int does, also when numba compiles this (an int exponent there
    # is repeated multiplication, which differs in the last bit)
    c3 = (10.0 * h - 4.0 * dv * T + 0.5 * da * T * T) / T ** 3.0
    c4 = (-15.0 * h + 7.0 * dv * T - da * T * T) / T ** 4.0
    c5 = (6.0 * h - 3.0 * dv * T + 0.5 * da * T * T) / T ** 5.0
    return q0, v0, 0.5 * a0, c3, c4, c5


class LeadIn:
    """Desired motion for t in [-duration_s, 0): from `start` (measured theta, omega; zero acceleration) to
    `target` = the trajectory's sample at t = 0."""

    def __init__(self, theta_rad: tuple[float, float], omega_rad_s: tuple[float, float], target: DesiredSample,
                 duration_s: float) -> None:
        if not duration_s > 0:
            raise TrajectoryError(f"lead-in duration must be > 0 s, got {duration_s}")
        self.duration_s = duration_s
        self._c = [quintic(theta_rad[j], omega_rad_s[j], 0.0, target.theta_rad[j], target.omega_rad_s[j],
                           target.alpha_rad_s2[j], duration_s) for j in (0, 1)]

    def sample(self, t_s: float) -> DesiredSample:
        """The lead-in at time t_s in [-duration_s, 0] (clamped)."""
        return DesiredSample(*lead_in_sample(self._c[0], self._c[1], self.duration_s, t_s))


def lead_in_duration_s(theta_rad: tuple[float, float], target: DesiredSample, min_s: float,
                       max_velocity_rad_s: float) -> float:
    """The lead-in's duration: `min_s` (`trajectory.lead_in_s`), or longer when the distance to cover needs it, so
    that the rest-to-rest part of the quintic peaks (1.875 x distance / duration) at `max_velocity_rad_s`. A start
    far from the trajectory (a controller started, or restarted, while the limb is elsewhere: after a safe-state stop)
    then reaches it without tripping the drive's velocity limit; a start on the trajectory's first sample (the default
    rest pose, whatever the gait's speed) keeps `min_s` exactly."""
    distance = max(abs(target.theta_rad[j] - theta_rad[j]) for j in (0, 1))
    return max(min_s, 1.875 * distance / max_velocity_rad_s) if min_s > 0 else min_s


def anchored_lead_in(theta_rad: tuple[float, float], omega_rad_s: tuple[float, float], target: DesiredSample,
                     min_ns: int, max_velocity_rad_s: float) -> tuple[int, LeadIn | None]:
    """The lead-in from a measured state at an anchor (the controller's first state, or the edge's INITIAL state):
    its duration in ns (`lead_in_duration_s`, at least `min_ns`) and the quintic, None when lead-ins are off
    (`min_ns` = 0). Both ends of the edge-trigger placement build it from the same state, so they agree on t."""
    if not min_ns:
        return 0, None
    lead_ns = int(round(lead_in_duration_s(theta_rad, target, min_ns * 1e-9, max_velocity_rad_s) * 1e9))
    lead_ns = max(lead_ns, min_ns)          # never shorter than configured (float round trip of min_ns)
    return lead_ns, LeadIn(theta_rad, omega_rad_s, target, lead_ns * 1e-9)


def lead_in_sample(c_hip: tuple[float, ...], c_knee: tuple[float, ...], duration_s: float, t_s: float
                   ) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
    """(theta, omega, alpha) pairs of the lead-in quintics (coefficients `quintic`) at t_s in [-duration_s, 0]
    (clamped); plain float code (the offline session kernel compiles it)."""
    tau = min(max(t_s + duration_s, 0.0), duration_s)
    h, k = quintic_at(c_hip, tau), quintic_at(c_knee, tau)
    return (h[0], k[0]), (h[1], k[1]), (h[2], k[2])


def quintic_at(c: tuple[float, ...], tau: float) -> tuple[float, float, float]:
    """(q, q', q'') of the quintic with coefficients c at tau."""
    q = c[0] + tau * (c[1] + tau * (c[2] + tau * (c[3] + tau * (c[4] + tau * c[5]))))
    qd = c[1] + tau * (2 * c[2] + tau * (3 * c[3] + tau * (4 * c[4] + tau * 5 * c[5])))
    qdd = 2 * c[2] + tau * (6 * c[3] + tau * (12 * c[4] + tau * 20 * c[5]))
    return q, qd, qdd


def _read_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            cols = [c.strip() for c in (reader.fieldnames or [])]
            missing = {"t", "theta1", "theta2"} - set(cols)
            if missing:
                raise TrajectoryError(f"{path}: missing column(s) {sorted(missing)}; need t, theta1, theta2")
            rows = [{k.strip(): v for k, v in row.items() if k is not None} for row in reader]
    except (OSError, UnicodeDecodeError) as err:
        raise TrajectoryError(f"cannot read trajectory {path}: {err}") from err
    if len(rows) < 4:
        raise TrajectoryError(f"{path}: need at least 4 rows, got {len(rows)}")
    try:
        data = np.array([[float(r["t"]), float(r["theta1"]), float(r["theta2"])] for r in rows])
    except (TypeError, ValueError) as err:
        raise TrajectoryError(f"{path}: non-numeric value ({err})") from err
    if not np.all(np.isfinite(data)):
        bad = int(np.argwhere(~np.isfinite(data))[0][0]) + 2
        raise TrajectoryError(f"{path}: NaN or infinite value on line {bad}")
    t = data[:, 0]
    if np.any(np.diff(t) <= 0):
        bad = int(np.argwhere(np.diff(t) <= 0)[0][0]) + 3
        raise TrajectoryError(f"{path}: time is not strictly increasing (line {bad})")
    return t, data[:, 1:]


def make_trajectory(cfg: TrajectoryConfig) -> GaitTrajectory | CsvTrajectory:
    if cfg.kind == "csv":
        if not cfg.csv_path:
            raise TrajectoryError("trajectory.kind = 'csv' needs trajectory.csv_path")
        return CsvTrajectory(cfg.csv_path)
    return GaitTrajectory(cfg.period_s)


def trajectory_id(cfg: TrajectoryConfig) -> int:
    """The trajectory's identity (u32): sha256 of its parameters and, for a CSV trajectory, the file's bytes. The edge
    sends it with every event state (EVENT_STATE.trajectory_id); a controller with another trajectory refuses it."""
    digest = hashlib.sha256(cfg.model_dump_json(exclude={"csv_path"}).encode())
    if cfg.kind == "csv":
        try:
            digest.update(Path(cfg.csv_path).read_bytes())
        except OSError as err:
            raise TrajectoryError(f"trajectory CSV {cfg.csv_path!r} not readable: {err}") from err
    return int.from_bytes(digest.digest()[:4], "little")

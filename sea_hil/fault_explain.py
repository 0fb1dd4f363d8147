"""One line a user can act on when a drive latches its safe state (issue 29 part 5): which limit, the measured value
against it, and who will clear the latch -- the edge (a watchdog trip, once setpoints are fresh again: its
CLEAR_ERRORS policy, controller/edge_core.py) or the user (a soft-limit fault, an e-stop).

Pure: `LatchWatch` takes HEARTBEATs and feedback values and says once per latch (a heartbeat in FAULT or ESTOP after
one that was not, or new flags during it) what happened. The edge core logs the line (controller/edge_core.py); the
recorder's CAN tap writes it to `/log/faults` (sea_hil/recorder/can_tap.py), where the live view shows it too.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

from sea_hil.config.safety import DriveLimitsConfig
from sea_hil.protocol.can_frames import LIMIT_FLAGS, DriverState, ErrorFlags, Heartbeat

JOINTS = ("hip", "knee")
SAFE = (DriverState.FAULT, DriverState.ESTOP)
LATCH_WORD = "latched"   # in every latch line (the live view picks them out of /log/faults by it)
POLICY_EDGE_CLEARS = "the edge clears it (CLEAR_ERRORS) once setpoints are fresh again (real time; never in lockstep)"
POLICY_USER = "needs the user: fix the cause, then CLEAR_ERRORS (the edge never clears a soft-limit fault or an e-stop)"
Pair = tuple[float, float]


def clear_policy(state: DriverState, flags: ErrorFlags | int) -> str:
    """Who ends a latch in `state` with `flags`."""
    if state is DriverState.ESTOP or flags & (LIMIT_FLAGS | ErrorFlags.ESTOP):
        return POLICY_USER
    return POLICY_EDGE_CLEARS


def latch_level(hb: Heartbeat) -> int:
    """The log level of a latch line: ERROR when it needs the user, INFO when the edge clears it itself (a watchdog
    trip: also the designed safe state at the end of every real-time session; the verdict counts one that happened
    during the session)."""
    return logging.ERROR if clear_policy(hb.state, hb.flags) == POLICY_USER else logging.INFO


def flag_names(flags: ErrorFlags | int) -> list[str]:
    """The names of the set error flags, in bit order."""
    return [f.name or "" for f in ErrorFlags if f & flags]


@dataclass
class Measured:
    """The newest feedback of one drive (None until seen)."""
    theta_rad: Pair | None = None
    omega_rad_s: Pair | None = None
    delta_m: Pair | None = None


def breaches(flags: ErrorFlags | int, m: Measured, limits: DriveLimitsConfig, stiffness_n_per_m: Pair) -> list[str]:
    """'<joint> <quantity> <value> <above/below> <key>[j] = <limit>' for each limit flag set whose measured value
    is outside its limit (the newest feedback: at most a sample after the one that faulted)."""
    out: list[str] = []
    checks = []
    if flags & ErrorFlags.POSITION_LIMIT and m.theta_rad is not None:
        checks += [("angle", m.theta_rad[j], limits.position_min_rad[j], limits.position_max_rad[j],
                    "safety.drive.position_min_rad", "safety.drive.position_max_rad", "rad", j) for j in (0, 1)]
    if flags & ErrorFlags.VELOCITY_LIMIT and m.omega_rad_s is not None:
        checks += [("velocity", m.omega_rad_s[j], -limits.velocity_max_rad_s[j], limits.velocity_max_rad_s[j],
                    "-safety.drive.velocity_max_rad_s", "safety.drive.velocity_max_rad_s", "rad/s", j) for j in (0, 1)]
    if flags & ErrorFlags.FORCE_LIMIT and m.delta_m is not None:
        checks += [("spring force", stiffness_n_per_m[j] * m.delta_m[j], -limits.spring_force_max_n[j],
                    limits.spring_force_max_n[j], "-safety.drive.spring_force_max_n",
                    "safety.drive.spring_force_max_n", "N", j) for j in (0, 1)]
    for what, v, lo, hi, lo_key, hi_key, unit, j in checks:
        if v > hi:
            out.append(f"{JOINTS[j]} {what} {v:.4g} {unit} above {hi_key}[{j}] = {hi:.4g} {unit}")
        elif v < lo:
            out.append(f"{JOINTS[j]} {what} {v:.4g} {unit} below {lo_key}[{j}] = {lo:.4g} {unit}")
    return out


def latch_line(hb: Heartbeat, m: Measured, limits: DriveLimitsConfig | None, stiffness_n_per_m: Pair) -> str:
    """The one line of a new latch (see the module docstring)."""
    flags = "|".join(flag_names(hb.flags)) or "no flags"
    why = breaches(hb.flags, m, limits, stiffness_n_per_m) if limits is not None else []
    if hb.flags & LIMIT_FLAGS and not why:
        why = ["the sample that faulted is not at hand (limits: [safety.drive])"]
    if hb.flags & ErrorFlags.WATCHDOG:
        why.append("no VOLTAGE_CMD within can.watchdog_timeout_s")
    because = f": {'; '.join(why)}" if why else ""
    return f"driver {hb.node_id} {LATCH_WORD} {hb.state.name} {flags}{because}; {clear_policy(hb.state, hb.flags)}"


@dataclass
class LatchWatch:
    """Per drive: the newest feedback and the latch state from heartbeats; `on_heartbeat` returns the line of a new
    latch (or of new flags during one) once, else None."""
    limits: DriveLimitsConfig | None
    stiffness_n_per_m: Pair
    measured: dict[int, Measured] = field(default_factory=dict)
    _latched: dict[int, ErrorFlags] = field(default_factory=dict)

    def feedback(self, node_id: int, theta_rad: Pair | None = None, omega_rad_s: Pair | None = None,
                 delta_m: Pair | None = None) -> None:
        m = self.measured.setdefault(node_id, Measured())
        if theta_rad is not None:
            m.theta_rad = theta_rad
        if omega_rad_s is not None:
            m.omega_rad_s = omega_rad_s
        if delta_m is not None:
            m.delta_m = delta_m

    def on_heartbeat(self, hb: Heartbeat, fb: Any = None) -> str | None:
        """The line of a new latch, or None; `fb` (anything with theta_rad, omega_rad_s, delta_m: the edge's newest
        Feedback) is taken as the drive's measured values first."""
        if fb is not None:
            self.feedback(hb.node_id, fb.theta_rad, fb.omega_rad_s, fb.delta_m)
        before = self._latched.get(hb.node_id)
        if hb.state not in SAFE:
            self._latched.pop(hb.node_id, None)
            return None
        flags = ErrorFlags(hb.flags)
        if before is not None and not flags & ~before:
            return None   # the same latch, nothing new
        self._latched[hb.node_id] = flags | (before or ErrorFlags(0))
        return latch_line(hb, self.measured.get(hb.node_id, Measured()), self.limits, self.stiffness_n_per_m)

"""The drive firmware's soft limits (ODrive `pos_min/pos_max`, `vel_limit`; moteus position and torque limits): joint
position and velocity and the SEA spring force, checked on every integrated sample. Pure: state in, the error flags
of the limits it violates out (`DriverCore` faults the drive on any)."""
from __future__ import annotations

from typing import NamedTuple

from sea_hil.config.safety import DriveLimitsConfig
from sea_hil.mechanics import LimbParams
from sea_hil.protocol.can_frames import ErrorFlags

INF = float("inf")


class DriveLimits(NamedTuple):
    position_min_rad: tuple[float, float] = (-INF, -INF)
    position_max_rad: tuple[float, float] = (INF, INF)
    velocity_max_rad_s: tuple[float, float] = (INF, INF)
    spring_force_max_n: tuple[float, float] = (INF, INF)

    @classmethod
    def from_config(cls, cfg: DriveLimitsConfig) -> DriveLimits:
        """The configured limits; none (every check passes) when `enabled` is false."""
        if not cfg.enabled:
            return cls()
        return cls(cfg.position_min_rad, cfg.position_max_rad, cfg.velocity_max_rad_s, cfg.spring_force_max_n)

    def violations(self, theta_rad: tuple[float, float], omega_rad_s: tuple[float, float],
                   deflection_m: tuple[float, float], p: LimbParams) -> ErrorFlags:
        """Flags of every limit the sample violates (ErrorFlags(0) if none); NaN violates every limit."""
        return ErrorFlags(limit_bits(self, theta_rad, omega_rad_s, deflection_m, p.k1, p.k2))


POSITION_BIT, VELOCITY_BIT, FORCE_BIT = (int(ErrorFlags.POSITION_LIMIT), int(ErrorFlags.VELOCITY_LIMIT),
                                         int(ErrorFlags.FORCE_LIMIT))


def limit_bits(lim: DriveLimits, theta_rad: tuple[float, float], omega_rad_s: tuple[float, float],
               deflection_m: tuple[float, float], k1: float, k2: float) -> int:
    """The `ErrorFlags` bits of every limit of `lim` the sample violates (0 if none; NaN violates every limit), for
    spring stiffnesses k1, k2. Plain float code: `DriverCore` runs it, and the offline engine's compiled drive
    (sea_hil/offline/drive_kernel.py) compiles it."""
    bits = 0
    stiffness = (k1, k2)
    for j in range(2):
        if not lim.position_min_rad[j] <= theta_rad[j] <= lim.position_max_rad[j]:
            bits |= POSITION_BIT
        if not abs(omega_rad_s[j]) <= lim.velocity_max_rad_s[j]:
            bits |= VELOCITY_BIT
        if not abs(stiffness[j] * deflection_m[j]) <= lim.spring_force_max_n[j]:
            bits |= FORCE_BIT
    return bits

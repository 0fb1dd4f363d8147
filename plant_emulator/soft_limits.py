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
        flags = ErrorFlags(0)
        stiffness = (p.k1, p.k2)
        for j in range(2):
            if not self.position_min_rad[j] <= theta_rad[j] <= self.position_max_rad[j]:
                flags |= ErrorFlags.POSITION_LIMIT
            if not abs(omega_rad_s[j]) <= self.velocity_max_rad_s[j]:
                flags |= ErrorFlags.VELOCITY_LIMIT
            if not abs(stiffness[j] * deflection_m[j]) <= self.spring_force_max_n[j]:
                flags |= ErrorFlags.FORCE_LIMIT
        return flags

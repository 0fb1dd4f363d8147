"""Config sections of the safety envelope (docs/can-protocol.md, "Safety envelope"): the limb's mechanical end stops
(`[plant.end_stops]`, part of the plant model), the drive firmware's soft limits (`[safety.drive]`) and the edge's
setpoint envelope (`[safety.setpoint]`). Every pair is (hip, knee). `enabled = false` removes the mechanism (the
paper's literal plant and controller, configs/paper.toml)."""
from __future__ import annotations

from pydantic import Field, model_validator

from sea_hil.config.base import Pair, _Frozen


def _ordered(lo: Pair, hi: Pair, what: str) -> None:
    for j in range(2):
        if not lo[j] < hi[j]:
            raise ValueError(f"{what}: joint {j + 1} minimum {lo[j]} is not below its maximum {hi[j]}")


def _positive(values: Pair, what: str) -> None:
    if not all(v > 0 for v in values):
        raise ValueError(f"{what} must be > 0, got {values}")


class EndStopConfig(_Frozen):
    """Mechanical joint end stops: a stiff spring-damper beyond [min_rad, max_rad] that pushes back and never pulls."""
    enabled: bool = True
    min_rad: Pair = (-1.0, -0.5)
    max_rad: Pair = (1.1, 1.6)
    stiffness_nm_per_rad: Pair = (1000.0, 1000.0)
    damping_nms_per_rad: Pair = (2.0, 2.0)

    @model_validator(mode="after")
    def _check(self) -> EndStopConfig:
        _ordered(self.min_rad, self.max_rad, "plant.end_stops")
        _positive(self.stiffness_nm_per_rad, "plant.end_stops.stiffness_nm_per_rad")
        if not all(c >= 0 for c in self.damping_nms_per_rad):
            raise ValueError("plant.end_stops.damping_nms_per_rad must be >= 0")
        return self


class DriveLimitsConfig(_Frozen):
    """Drive firmware soft limits, checked on every sample while RUNNING: leaving one faults the drive (0 V) with
    its own heartbeat flag (err_position_limit, err_velocity_limit, err_force_limit) until CLEAR_ERRORS."""
    enabled: bool = True
    position_min_rad: Pair = (-0.56, -0.04)
    position_max_rad: Pair = (0.66, 1.30)
    velocity_max_rad_s: Pair = (2.0, 2.0)
    spring_force_max_n: Pair = (60.0, 60.0)

    @model_validator(mode="after")
    def _check(self) -> DriveLimitsConfig:
        _ordered(self.position_min_rad, self.position_max_rad, "safety.drive position")
        _positive(self.velocity_max_rad_s, "safety.drive.velocity_max_rad_s")
        _positive(self.spring_force_max_n, "safety.drive.spring_force_max_n")
        return self


class SetpointEnvelopeConfig(_Frozen):
    """The edge rejects (and counts) a SETPOINT whose deflection v_x is not finite or exceeds deflection_max_m."""
    enabled: bool = True
    deflection_max_m: Pair = Field((0.002, 0.002))
    resume_ramp_s: float = Field(0.05, ge=0, description="bumpless resume after the drive's safe state: the edge ramps "
                                 "the deflection command from the measured deflection to the setpoint over this time "
                                 "and restarts its observer; 0 = off (a step, the stale observer)")
    max_sample_age_s: float = Field(0.003, ge=0, description="real time: the edge sends a VOLTAGE_CMD only for a "
                                    "feedback sample received at most this long ago (a starved edge working through "
                                    "a backlog answers only the newest samples; the drive's watchdog acts if it "
                                    "stays behind); 0 = off (every sample answered)")
    max_answer_age_s: float = Field(0.2, ge=0, description="the edge applies a setpoint/voltage only if the state it "
                                    "answers was sampled at most this long before (sample time, so lockstep too); a "
                                    "later one is counted (late_setpoints), logged and dropped, and the edge's answer "
                                    "timeout (the local fallback) is capped at it: a starved or congested controller "
                                    "path cannot steer the limb on old states; 0 = off")

    @model_validator(mode="after")
    def _check(self) -> SetpointEnvelopeConfig:
        _positive(self.deflection_max_m, "safety.setpoint.deflection_max_m")
        return self


class SafetyConfig(_Frozen):
    drive: DriveLimitsConfig = DriveLimitsConfig()
    setpoint: SetpointEnvelopeConfig = SetpointEnvelopeConfig()

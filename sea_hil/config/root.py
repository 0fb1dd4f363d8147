"""`SeaHilConfig`: every section of one process's configuration."""
from __future__ import annotations

import math

from pydantic import field_validator, model_validator

from sea_hil.config.base import _Frozen
from sea_hil.config.comms import CanConfig, LinkConfig, RecordConfig, ZenohConfig
from sea_hil.config.limbs import LimbConfig, check_limbs
from sea_hil.config.live import LiveConfig
from sea_hil.config.model import (
    ControllerConfig,
    DisturbanceConfig,
    PlantConfig,
    SimConfig,
    TrajectoryConfig,
    TriggerConfig,
)
from sea_hil.config.safety import SafetyConfig
from sea_hil.config.timing import TimingConfig
from sea_hil.config.verdict import VerdictConfig


class SeaHilConfig(_Frozen):
    plant: PlantConfig
    disturbance: DisturbanceConfig = DisturbanceConfig()
    trajectory: TrajectoryConfig = TrajectoryConfig()
    controller: ControllerConfig
    trigger: TriggerConfig
    sim: SimConfig = SimConfig()
    can: CanConfig = CanConfig()
    zenoh: ZenohConfig = ZenohConfig()
    link: LinkConfig = LinkConfig()
    record: RecordConfig = RecordConfig()
    live: LiveConfig = LiveConfig()
    safety: SafetyConfig = SafetyConfig()
    timing: TimingConfig = TimingConfig()   # [timing]: real-time levers of the 1 kHz loops (docs/timing.md)
    verdict: VerdictConfig = VerdictConfig()   # [verdict]: ok / degraded / invalid thresholds (docs/verdict.md)
    limbs: tuple[LimbConfig, ...] = ()   # [[limbs]]; empty = the one default limb (sea_hil/config/limbs.py)

    @field_validator("limbs")
    @classmethod
    def _limbs(cls, v: tuple[LimbConfig, ...]) -> tuple[LimbConfig, ...]:
        return check_limbs(v)

    @field_validator("plant")
    @classmethod
    def _finite(cls, v: PlantConfig) -> PlantConfig:
        for name, val in v.model_dump().items():
            vals = val if isinstance(val, (tuple, list)) else (val,)
            if any(isinstance(x, float) and not math.isfinite(x) for x in vals):
                raise ValueError(f"plant.{name} must be finite")
        return v

    @model_validator(mode="after")
    def _rates(self) -> SeaHilConfig:
        """One outer sample = a whole number (>= 1) of inner steps, offline and in sessions."""
        ratio = self.controller.sample_period_s * self.can.feedback_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(f"controller.sample_period_s ({self.controller.sample_period_s} s) must be a whole number "
                             f"(>= 1) of inner-loop periods (1 / can.feedback_rate_hz = "
                             f"{1.0 / self.can.feedback_rate_hz} s)")
        return self

"""`SeaHilConfig`: every section of one process's configuration."""
from __future__ import annotations

import math

from pydantic import field_validator

from sea_hil.config.base import _Frozen
from sea_hil.config.comms import CanConfig, LinkConfig, RecordConfig, ZenohConfig
from sea_hil.config.model import (ControllerConfig, DisturbanceConfig, PlantConfig, SimConfig, TrajectoryConfig,
                                  TriggerConfig)
from sea_hil.config.safety import SafetyConfig


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
    safety: SafetyConfig = SafetyConfig()

    @field_validator("plant")
    @classmethod
    def _finite(cls, v: PlantConfig) -> PlantConfig:
        for name, val in v.model_dump().items():
            vals = val if isinstance(val, (tuple, list)) else (val,)
            if any(isinstance(x, float) and not math.isfinite(x) for x in vals):
                raise ValueError(f"plant.{name} must be finite")
        return v

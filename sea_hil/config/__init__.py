"""Frozen configuration objects loaded from TOML.

One `SeaHilConfig` is built per process from the embedded default (`sea_hil/config/default_config.toml`) overlaid with
an optional user file; unknown keys and wrong types are errors (`ConfigError`, one line). Nothing here is global:
callers pass the config object down.
"""
from __future__ import annotations

from sea_hil.config.base import Pair
from sea_hil.config.comms import (CanConfig, LinkConfig, LinkDirectionConfig, RecordConfig, ZenohAclConfig, ZenohConfig,
                                  ZenohTlsConfig)
from sea_hil.config.limbs import LimbConfig
from sea_hil.config.live import LiveConfig
from sea_hil.config.loader import config_from_dict, config_to_toml, default_toml_text, load_config
from sea_hil.config.model import (ControllerConfig, DisturbanceConfig, PlantConfig, SimConfig, TrajectoryConfig,
                                  TriggerConfig)
from sea_hil.config.root import SeaHilConfig
from sea_hil.config.safety import DriveLimitsConfig, EndStopConfig, SafetyConfig, SetpointEnvelopeConfig
from sea_hil.config.verdict import VerdictConfig

__all__ = ["CanConfig", "ControllerConfig", "DisturbanceConfig", "DriveLimitsConfig", "EndStopConfig", "LinkConfig",
           "LimbConfig", "LinkDirectionConfig", "LiveConfig", "Pair", "PlantConfig", "RecordConfig", "SafetyConfig", "SeaHilConfig",
           "SetpointEnvelopeConfig", "SimConfig", "TrajectoryConfig", "TriggerConfig",
           "VerdictConfig", "ZenohAclConfig", "ZenohConfig", "ZenohTlsConfig", "config_from_dict", "config_to_toml",
           "default_toml_text", "load_config"]

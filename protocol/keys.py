"""Zenoh key expressions of one limb: `<prefix>/<limb>/<channel>` (see docs/zenoh-protocol.md).

| channel    | direction           | content                                                         |
|------------|---------------------|-----------------------------------------------------------------|
| `state`    | edge -> controller  | sampled joint state (`StatePayload`, binary)                    |
| `setpoint` | controller -> edge  | spring-deflection setpoint v_x(t_i), only on events (binary)    |
| `voltage`  | controller -> edge  | motor voltages for the "remote inner loop" placement (binary)   |
| `stats`    | any node -> all     | periodic node statistics (JSON object)                          |
| `event`    | controller -> all   | trigger events with their reason (JSON object)                  |
| `control`  | any -> all          | session control, e.g. lockstep / stop (JSON object, generic)    |
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from sea_hil.config.wire_names import validate_limb, validate_prefix
from sea_hil.errors import ConfigError

CHANNELS: tuple[str, ...] = ("state", "setpoint", "voltage", "stats", "event", "control")
class _KeyedConfig(Protocol):
    """What `Keys.from_config` reads (a `ZenohConfig`; the wire layer does not import the config)."""

    @property
    def prefix(self) -> str: ...

    @property
    def limb(self) -> str: ...


@dataclass(frozen=True)
class Keys:
    """All key expressions of one limb. Build with `Keys.make(prefix, limb)` or `Keys.from_config(zenoh_cfg)`."""
    prefix: str
    limb: str
    state: str
    setpoint: str
    voltage: str
    stats: str
    event: str
    control: str

    @classmethod
    def make(cls, prefix: str, limb: str) -> Keys:
        validate_prefix(prefix)
        validate_limb(limb)
        base = f"{prefix}/{limb}"
        return cls(prefix, limb, **{ch: f"{base}/{ch}" for ch in CHANNELS})

    @classmethod
    def from_config(cls, zenoh_cfg: _KeyedConfig) -> Keys:
        """From a `sea_hil.config.ZenohConfig` (anything with `.prefix` and `.limb`)."""
        return cls.make(zenoh_cfg.prefix, zenoh_cfg.limb)

    def all(self) -> dict[str, str]:
        """Channel name -> key expression."""
        return {ch: getattr(self, ch) for ch in CHANNELS}


def any_limb(prefix: str, channel: str) -> str:
    """Wildcard selector `<prefix>/*/<channel>` over all limbs (for recorders and monitors)."""
    validate_prefix(prefix)
    if channel not in CHANNELS:
        raise ConfigError(f"unknown channel {channel!r}; expected one of {', '.join(CHANNELS)}")
    return f"{prefix}/*/{channel}"


def everything(prefix: str) -> str:
    """Selector `<prefix>/**` matching every key of every limb."""
    return f"{validate_prefix(prefix)}/**"

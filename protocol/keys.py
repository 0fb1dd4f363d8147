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
from sea_hil.protocol.payloads import MsgType

CHANNELS: tuple[str, ...] = ("state", "setpoint", "voltage", "stats", "event", "control")
KEY_PAYLOADS: dict[str, frozenset[MsgType]] = {
    "state": frozenset({MsgType.STATE, MsgType.EVENT_STATE}),
    "setpoint": frozenset({MsgType.SETPOINT}),
    "voltage": frozenset({MsgType.VOLTAGE}),
    "control": frozenset({MsgType.ACK}),
}
KEY_CONGESTION: dict[str, tuple[str, str]] = {
    "state": ("DROP", "BLOCK"), "setpoint": ("DROP", "BLOCK"), "voltage": ("DROP", "BLOCK"),
    "control": ("DROP", "BLOCK"), "event": ("BLOCK", "BLOCK"), "stats": ("DROP", "DROP"),
}
"""Zenoh congestion control per key (real time, lockstep), as the built-in nodes publish (tests/test_key_table.py
checks it against the runtime's syncs and nodes): in real time a late control message is worth less than the next
one (DROP); a lockstep run must be complete to be reproducible (BLOCK); tracking records are never dropped."""
KEY_RATES: dict[str, str] = {
    "state": "every `controller.sample_period_s` (10 ms; with the trigger at the edge only on events)",
    "setpoint": "on events only: <= 1/`controller.sample_period_s`, >= 1/`trigger.max_inter_event_s`",
    "voltage": "every state (remote inner-loop placement only)",
    "control": "lockstep: one ACK per handled state",
    "event": "one tracking record per handled state",
    "stats": "at node shutdown (`final: true`; the record's required fields: docs/recording.md)",
}
KEY_DIRECTION: dict[str, str] = {"state": "edge -> controller", "setpoint": "controller -> edge",
                                 "voltage": "controller -> edge", "control": "controller -> edge",
                                 "event": "controller (or edge) -> all", "stats": "every node -> all"}
"""The binary payload types each key carries (the JSON keys `stats` and `event` none): every receiver decodes with
`PayloadCounters.try_decode(data, KEY_PAYLOADS[channel])`, so a well-formed payload on the wrong key is rejected
(`payload_rejected_key`) and never reaches sequence tracking (issue 29: a VOLTAGE on the setpoint key was applied)."""


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

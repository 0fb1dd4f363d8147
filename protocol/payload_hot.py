"""The hot senders' encoders: a STATE or EVENT_STATE (edge -> controller) or SETPOINT (controller -> edge) payload from
its fields in one `struct` call, without building the payload object first (docs/timing.md, "Zenoh hop": every line
of Python per message costs several times its hot price right after a wake-up).

The bytes and the verdicts are those of `encode(StatePayload(...))` / `encode(EventStatePayload(...))` /
`encode(SetpointPayload(...))` (tests/test_payload_hot.py): the one-call path is taken only when every integer is an
`int`, every pair has two elements, the floats' sum is finite and the reason is a `TriggerReason`; anything else, or
a value `struct` refuses, goes through the payload's constructor, which converts it or raises its exact
`PayloadRejected`.
"""
from __future__ import annotations

import struct
from collections.abc import Sequence
from math import isfinite
from typing import Any

from sea_hil.protocol.payloads import (
    MAGIC,
    VERSION,
    WHOLE,
    EventStatePayload,
    MsgType,
    SetpointPayload,
    StatePayload,
    TriggerReason,
    encode,
)

__all__ = ["encode_event_state", "encode_setpoint", "encode_state"]

_STATE = WHOLE[MsgType.STATE]
_EVENT_STATE = WHOLE[MsgType.EVENT_STATE]
_SETPOINT = WHOLE[MsgType.SETPOINT]
_REFUSED = (struct.error, OverflowError, TypeError)
Pair = Sequence[float]


def encode_state(seq: int, t_ns: int, sample_t_ns: int, theta_rad: Pair, omega_rad_s: Pair, delta_m: Pair,
                 nut_vel_m_s: Pair, *, epoch: int = 0) -> bytes:
    """The bytes of `encode(StatePayload(seq, t_ns, sample_t_ns, theta_rad, omega_rad_s, delta_m, nut_vel_m_s,
    epoch=epoch))`."""
    try:
        if (type(seq) is int and type(t_ns) is int and type(sample_t_ns) is int and type(epoch) is int
                and len(theta_rad) == len(omega_rad_s) == len(delta_m) == len(nut_vel_m_s) == 2
                and isfinite(theta_rad[0] + theta_rad[1] + omega_rad_s[0] + omega_rad_s[1] + delta_m[0] + delta_m[1]
                             + nut_vel_m_s[0] + nut_vel_m_s[1])):
            return _STATE.pack(MAGIC, VERSION, MsgType.STATE, seq, t_ns, epoch, sample_t_ns, *theta_rad,
                               *omega_rad_s, *delta_m, *nut_vel_m_s)
    except _REFUSED:
        pass
    return encode(StatePayload(seq, t_ns, sample_t_ns, theta_rad, omega_rad_s, delta_m, nut_vel_m_s,  # type: ignore
                               epoch=epoch))


def encode_setpoint(seq: int, t_ns: int, state_seq: int, deflection_m: Pair, sliding: Pair, reason: TriggerReason,
                    *, epoch: int = 0) -> bytes:
    """The bytes of `encode(SetpointPayload(seq, t_ns, state_seq, deflection_m, sliding, reason, epoch=epoch))`."""
    try:
        if (type(seq) is int and type(t_ns) is int and type(state_seq) is int and type(epoch) is int
                and type(reason) is TriggerReason and len(deflection_m) == len(sliding) == 2
                and isfinite(deflection_m[0] + deflection_m[1] + sliding[0] + sliding[1])):
            return _SETPOINT.pack(MAGIC, VERSION, MsgType.SETPOINT, seq, t_ns, epoch, state_seq, *deflection_m,
                                  *sliding, reason)
    except _REFUSED:
        pass
    return encode(SetpointPayload(seq, t_ns, state_seq, deflection_m, sliding, reason,  # type: ignore[arg-type]
                                  epoch=epoch))


def encode_event_state(seq: int, t_ns: int, sample_t_ns: int, theta_rad: Pair, omega_rad_s: Pair, delta_m: Pair,
                       nut_vel_m_s: Pair, event_seq: int, reason: TriggerReason, trajectory_id: int, *,
                       epoch: int = 0) -> bytes:
    """The bytes of `encode(EventStatePayload(seq, t_ns, sample_t_ns, theta_rad, omega_rad_s, delta_m, nut_vel_m_s,
    event_seq, reason, trajectory_id, epoch=epoch))`."""
    try:
        if (type(seq) is int and type(t_ns) is int and type(sample_t_ns) is int and type(epoch) is int
                and type(event_seq) is int and type(trajectory_id) is int and type(reason) is TriggerReason
                and len(theta_rad) == len(omega_rad_s) == len(delta_m) == len(nut_vel_m_s) == 2
                and isfinite(theta_rad[0] + theta_rad[1] + omega_rad_s[0] + omega_rad_s[1] + delta_m[0] + delta_m[1]
                             + nut_vel_m_s[0] + nut_vel_m_s[1])):
            return _EVENT_STATE.pack(MAGIC, VERSION, MsgType.EVENT_STATE, seq, t_ns, epoch, sample_t_ns, *theta_rad,
                                     *omega_rad_s, *delta_m, *nut_vel_m_s, event_seq, reason, trajectory_id)
    except _REFUSED:
        pass
    checked: Any = EventStatePayload   # the constructor converts or rejects what the one-call path did not take
    return encode(checked(seq, t_ns, sample_t_ns, theta_rad, omega_rad_s, delta_m, nut_vel_m_s, event_seq, reason,
                          trajectory_id, epoch=epoch))

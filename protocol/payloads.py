"""Versioned binary Zenoh payloads (little-endian `struct`): layouts, encoder, decoder and decode counters.

Common 24-byte header: magic `b"SH"` (2 bytes), version (u8), msg type (u8), seq (u32), t_ns (u64, monotonic ns of
the sender at send time), epoch (u64, the sender's session epoch: `sea_hil.protocol.epoch`). Bodies (floats are
float64 so lockstep runs are bit-reproducible):

- STATE    (1): sample_t_ns u64, theta[2], omega[2], delta[2], nut_vel[2] f64            -> 96 bytes total
- SETPOINT (2): state_seq u32, deflection_m[2] f64, sliding[2] f64, reason u8           -> 61 bytes total
- VOLTAGE  (3): state_seq u32, voltage_v[2] f64                                          -> 44 bytes total
- ACK      (4): state_seq u32, setpoint_seq u32, sent u8 (lockstep: controller handled state_seq) -> 33 bytes
- EVENT_STATE (5): STATE's body + event_seq u32, reason u8, trajectory_id u32 (trigger at the edge) -> 105 bytes

Versioning: `VERSION` is bumped on any change of an existing layout; a decoder rejects every version it does not
know. New message types may be added without a bump (old decoders reject them as unknown type). Lengths are exact.

Also importable from here (their own modules): field validation and `PayloadRejected` (payload_fields.py), sequence
tracking (sequence.py), the wire-size estimate (wire_size.py).
"""
from __future__ import annotations

import logging
import struct
import threading
from collections import Counter
from dataclasses import dataclass, field
from enum import IntEnum
from math import isfinite
from typing import Any, ClassVar

from sea_hil.protocol.payload_fields import U32_MAX, U64_MAX, PayloadRejected, RejectReason, pair_field, uint_field

__all__ = ["HEADER_SIZE", "MAGIC", "PAYLOAD_SIZE", "SUPPORTED_VERSIONS", "VERSION", "AckPayload", "EventStatePayload",
           "MsgType", "Payload", "PayloadCounters", "SetpointPayload", "StatePayload", "TriggerReason",
           "VoltagePayload", "decode", "encode"]

_log = logging.getLogger("sea_hil.protocol")
MAGIC = b"SH"
VERSION = 2          # 2: `epoch` added to the header (issue 19)
SUPPORTED_VERSIONS = frozenset({VERSION})
_HEADER = struct.Struct("<2sBBIQQ")
HEADER_SIZE = _HEADER.size  # 24


class MsgType(IntEnum):
    STATE = 1
    SETPOINT = 2
    VOLTAGE = 3
    ACK = 4
    EVENT_STATE = 5


class TriggerReason(IntEnum):
    """Why the controller transmitted a setpoint."""
    TIME = 0            # periodic (time-triggered baseline)
    ERROR_BOUND = 1     # the ||e|| rule of Eq. 19
    TRACKING_BOUND = 2  # ||X~|| > r
    HEARTBEAT = 3       # maximum inter-event time elapsed
    INITIAL = 4         # first setpoint of a session


_MSG_TYPES = {int(m): m for m in MsgType}   # dict lookups in `decode`: an enum call costs ~10x more per message
_REASONS = {int(r): r for r in TriggerReason}


def trigger_reason(v: int) -> TriggerReason:
    """`v` as a `TriggerReason`, else PayloadRejected(ENUM) (`v` may be anything a sender put in the field)."""
    try:
        return TriggerReason(v)
    except ValueError as err:
        raise PayloadRejected(RejectReason.ENUM, f"trigger reason {v!r} is unknown") from err


@dataclass(frozen=True)
class _Payload:
    """Base validating the common fields and float pairs (named in `_pairs`) after construction. `epoch` (keyword
    only; 0 = none given) is the sender's session epoch (`sea_hil.protocol.epoch`)."""
    epoch: int = field(default=0, kw_only=True)
    _pairs: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        uint_field("seq", self.seq, U32_MAX)  # type: ignore[attr-defined]
        uint_field("t_ns", self.t_ns, U64_MAX)  # type: ignore[attr-defined]
        uint_field("epoch", self.epoch, U64_MAX)
        for name in self._pairs:
            v = getattr(self, name)
            checked = pair_field(name, v)
            if checked is not v:   # converted (e.g. a list or ints): store the tuple of floats
                object.__setattr__(self, name, checked)


@dataclass(frozen=True)
class StatePayload(_Payload):
    seq: int
    t_ns: int
    sample_t_ns: int
    theta_rad: tuple[float, float]
    omega_rad_s: tuple[float, float]
    delta_m: tuple[float, float]
    nut_vel_m_s: tuple[float, float]
    _pairs: ClassVar[tuple[str, ...]] = ("theta_rad", "omega_rad_s", "delta_m", "nut_vel_m_s")

    def __post_init__(self) -> None:
        super().__post_init__()
        uint_field("sample_t_ns", self.sample_t_ns, U64_MAX)


@dataclass(frozen=True)
class EventStatePayload(StatePayload):
    """A state the edge's trigger published (issue 16): why (`reason`), which event it is (`event_seq`: consecutive,
    so the controller counts lost states although the header seq, the sample index + 1, has gaps) and the identity of
    the trajectory the edge triggers on (`trajectory_id`)."""
    event_seq: int = 0
    reason: TriggerReason = TriggerReason.TIME
    trajectory_id: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        uint_field("event_seq", self.event_seq, U32_MAX)
        uint_field("trajectory_id", self.trajectory_id, U32_MAX)
        if type(self.reason) is not TriggerReason:
            object.__setattr__(self, "reason", trigger_reason(self.reason))


@dataclass(frozen=True)
class SetpointPayload(_Payload):
    seq: int
    t_ns: int
    state_seq: int
    deflection_m: tuple[float, float]
    sliding: tuple[float, float]
    reason: TriggerReason
    _pairs: ClassVar[tuple[str, ...]] = ("deflection_m", "sliding")

    def __post_init__(self) -> None:
        super().__post_init__()
        uint_field("state_seq", self.state_seq, U32_MAX)
        if type(self.reason) is not TriggerReason:
            object.__setattr__(self, "reason", trigger_reason(self.reason))


@dataclass(frozen=True)
class VoltagePayload(_Payload):
    seq: int
    t_ns: int
    state_seq: int
    voltage_v: tuple[float, float]
    _pairs: ClassVar[tuple[str, ...]] = ("voltage_v",)

    def __post_init__(self) -> None:
        super().__post_init__()
        uint_field("state_seq", self.state_seq, U32_MAX)


@dataclass(frozen=True)
class AckPayload(_Payload):
    """Lockstep control plane: the controller has handled state `state_seq`; `sent` says whether that produced
    setpoint `setpoint_seq` (which the edge then waits for). Not counted as a downlink transmission."""
    seq: int
    t_ns: int
    state_seq: int
    setpoint_seq: int
    sent: bool

    def __post_init__(self) -> None:
        super().__post_init__()
        uint_field("state_seq", self.state_seq, U32_MAX)
        uint_field("setpoint_seq", self.setpoint_seq, U32_MAX)
        object.__setattr__(self, "sent", bool(self.sent))


Payload = StatePayload | EventStatePayload | SetpointPayload | VoltagePayload | AckPayload

_BODY = {
    MsgType.STATE: struct.Struct("<Q8d"),
    MsgType.SETPOINT: struct.Struct("<I4dB"),
    MsgType.VOLTAGE: struct.Struct("<I2d"),
    MsgType.ACK: struct.Struct("<IIB"),
    MsgType.EVENT_STATE: struct.Struct("<Q8dIBI"),
}
_TYPE_OF = {StatePayload: MsgType.STATE, SetpointPayload: MsgType.SETPOINT, VoltagePayload: MsgType.VOLTAGE,
            AckPayload: MsgType.ACK, EventStatePayload: MsgType.EVENT_STATE}
PAYLOAD_SIZE = {t: HEADER_SIZE + s.size for t, s in _BODY.items()}
# header and body in one struct, for the hot messages (STATE or EVENT_STATE up, SETPOINT down): keyed by their first
# four bytes
WHOLE = {t: struct.Struct(_HEADER.format + _BODY[t].format[1:])
         for t in (MsgType.STATE, MsgType.SETPOINT, MsgType.EVENT_STATE)}
_HOT = {MAGIC + bytes((VERSION, t)): s for t, s in WHOLE.items()}
_HOT_CLASS = {MsgType.STATE: StatePayload, MsgType.SETPOINT: SetpointPayload,
              MsgType.EVENT_STATE: EventStatePayload}


def encode(p: Payload) -> bytes:
    """Serialise a (constructor-validated) payload."""
    mtype = _TYPE_OF.get(type(p))
    if mtype is None:
        raise PayloadRejected(RejectReason.TYPE, f"cannot encode {type(p).__name__}")
    head = _HEADER.pack(MAGIC, VERSION, mtype, p.seq, p.t_ns, p.epoch)
    if isinstance(p, EventStatePayload):
        body = _BODY[mtype].pack(p.sample_t_ns, *p.theta_rad, *p.omega_rad_s, *p.delta_m, *p.nut_vel_m_s,
                                 p.event_seq, int(p.reason), p.trajectory_id)
    elif isinstance(p, StatePayload):
        body = _BODY[mtype].pack(p.sample_t_ns, *p.theta_rad, *p.omega_rad_s, *p.delta_m, *p.nut_vel_m_s)
    elif isinstance(p, SetpointPayload):
        body = _BODY[mtype].pack(p.state_seq, *p.deflection_m, *p.sliding, int(p.reason))
    elif isinstance(p, AckPayload):
        body = _BODY[mtype].pack(p.state_seq, p.setpoint_seq, int(p.sent))
    else:
        body = _BODY[mtype].pack(p.state_seq, *p.voltage_v)
    return head + body


def decode(b: bytes) -> Payload:
    """Parse and validate one payload; raises `PayloadRejected` (a `MalformedPayload`) with the reason."""
    b = bytes(b)
    hot = _HOT.get(b[:4])
    if hot is not None and len(b) == hot.size:      # the hot messages: one `struct` call (docs/timing.md)
        p = _hot(hot.unpack(b))
        if p is not None:
            return p
    if len(b) < HEADER_SIZE:
        raise PayloadRejected(RejectReason.LENGTH, f"{len(b)} bytes is shorter than the {HEADER_SIZE}-byte header")
    magic, version, mtype, seq, t_ns, epoch = _HEADER.unpack_from(b)
    if magic != MAGIC:
        raise PayloadRejected(RejectReason.MAGIC, f"magic {magic!r} != {MAGIC!r}")
    if version not in SUPPORTED_VERSIONS:
        raise PayloadRejected(RejectReason.VERSION, f"version {version} not supported ({sorted(SUPPORTED_VERSIONS)})")
    mt = _MSG_TYPES.get(mtype)
    if mt is None:                  # rare: the enum's own error is the cause (the fast lookup has none to keep)
        try:
            mt = MsgType(mtype)
        except ValueError as err:
            raise PayloadRejected(RejectReason.TYPE, f"unknown message type {mtype}") from err
    if len(b) != PAYLOAD_SIZE[mt]:
        raise PayloadRejected(RejectReason.LENGTH, f"{mt.name} must be {PAYLOAD_SIZE[mt]} bytes, got {len(b)}")
    f = _BODY[mt].unpack_from(b, HEADER_SIZE)
    if mt is MsgType.STATE:
        return StatePayload(seq, t_ns, f[0], f[1:3], f[3:5], f[5:7], f[7:9], epoch=epoch)
    if mt is MsgType.EVENT_STATE:
        return EventStatePayload(seq, t_ns, f[0], f[1:3], f[3:5], f[5:7], f[7:9], f[9], _REASONS.get(f[10], f[10]), f[11],
                                 epoch=epoch)
    if mt is MsgType.SETPOINT:
        return SetpointPayload(seq, t_ns, f[0], f[1:3], f[3:5], _REASONS.get(f[5], f[5]), epoch=epoch)
    if mt is MsgType.ACK:
        if f[2] > 1:
            raise PayloadRejected(RejectReason.ENUM, f"ack flag {f[2]} is not 0 or 1")
        return AckPayload(seq, t_ns, f[0], f[1], f[2], epoch=epoch)
    return VoltagePayload(seq, t_ns, f[0], f[1:3], epoch=epoch)


def _hot(f: tuple[Any, ...]) -> Payload | None:
    """A STATE, EVENT_STATE or SETPOINT from its whole-message unpack `f` without re-running the constructors'
    checks, when they cannot fail: `struct` gives in-range unsigned integers, and one `isfinite` of the floats' sum
    is true only if every float is finite (an overflowing sum of finite floats is false: the constructor then
    decides); a reason byte must be a known `TriggerReason`. None: take the general path (whose constructor raises
    the exact rejection)."""
    obj: StatePayload | EventStatePayload | SetpointPayload = object.__new__(_HOT_CLASS[f[2]])
    if f[2] != MsgType.SETPOINT:
        if not isfinite(sum(f[7:15])):
            return None
        obj.__dict__.update(seq=f[3], t_ns=f[4], epoch=f[5], sample_t_ns=f[6], theta_rad=f[7:9],
                            omega_rad_s=f[9:11], delta_m=f[11:13], nut_vel_m_s=f[13:15])
        if f[2] == MsgType.EVENT_STATE:
            reason = _REASONS.get(f[16])
            if reason is None:
                return None
            obj.__dict__.update(event_seq=f[15], reason=reason, trajectory_id=f[17])
        return obj
    reason = _REASONS.get(f[11])
    if reason is None or not isfinite(sum(f[7:11])):
        return None
    obj.__dict__.update(seq=f[3], t_ns=f[4], epoch=f[5], state_seq=f[6], deflection_m=f[7:9], sliding=f[9:11],
                        reason=reason)
    return obj


class OncePerVersion(logging.Filter):
    """Lets the first "foreign payload version" line per version through, per process: the nodes of one `sea-hil
    run` (edge, recorder, the external-controller watch) share a process and each decodes the same payload, so each
    logged it once (issue 29: three lines for one foreign peer). Process-wide like the logger it is attached to."""

    def __init__(self) -> None:
        super().__init__()
        self._seen: set[int] = set()
        self._lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        version = getattr(record, "payload_version", None)
        if version is None:
            return True
        with self._lock:
            new = version not in self._seen
            self._seen.add(version)
        return new

    def reset(self) -> None:
        """Forget the versions logged (a test that checks the one line runs after others that logged it)."""
        with self._lock:
            self._seen.clear()


FOREIGN_VERSION_LOG = OncePerVersion()
_log.addFilter(FOREIGN_VERSION_LOG)


class PayloadCounters:
    """Accepted / rejected-by-reason counters around `decode` (never raises on bad input)."""

    def __init__(self) -> None:
        self.accepted = 0
        self.rejected: Counter[str] = Counter()
        self.last_error = ""
        self._versions_logged: set[int] = set()
        self._key_logged: set[tuple[int, frozenset[MsgType]]] = set()

    def try_decode(self, b: bytes, accepts: frozenset[MsgType] | None = None) -> Payload | None:
        """Decode `b`, counting the outcome; None if it was rejected. `accepts`: the message types the key it came
        on carries (protocol/keys.py, `KEY_PAYLOADS`); a well-formed payload of another type is rejected as KEY
        before anything else sees it (so it never moves sequence state). The first payload of every foreign layout
        version is logged once per process (a peer of another sea-hil release), later ones only counted."""
        try:
            p = decode(b)
        except PayloadRejected as err:
            self.rejected[err.reason.value] += 1
            self.last_error = str(err)
            if err.reason is RejectReason.VERSION and b[2] not in self._versions_logged:
                self._versions_logged.add(b[2])
                _log.warning("a peer sends payload version %d, this node speaks %s: its messages are dropped and "
                             "counted (payload_rejected_version); run the same sea-hil release on both sides",
                             b[2], "/".join(map(str, sorted(SUPPORTED_VERSIONS))), extra={"payload_version": b[2]})
            return None
        mtype = _TYPE_OF[type(p)]
        if accepts is not None and mtype not in accepts:
            self.rejected[RejectReason.KEY.value] += 1
            self.last_error = f"malformed payload (key): {mtype.name} on a key that carries " \
                              f"{'/'.join(sorted(t.name for t in accepts))}"
            if (mtype, accepts) not in self._key_logged:
                self._key_logged.add((mtype, accepts))
                _log.warning("%s: dropped and counted (payload_rejected_key)", self.last_error)
            return None
        self.accepted += 1
        return p

    def as_dict(self) -> dict[str, object]:
        return {"accepted": self.accepted, "rejected": dict(self.rejected),
                "rejected_total": sum(self.rejected.values())}

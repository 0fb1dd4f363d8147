"""Versioned binary Zenoh payloads (little-endian `struct`), their decoder, counters and sequence tracking.

Common 16-byte header: magic `b"SH"` (2 bytes), version (u8), msg type (u8), seq (u32), t_ns (u64, monotonic ns of
the sender at send time). Bodies (floats are float64 so lockstep runs are bit-reproducible):

- STATE    (1): sample_t_ns u64, theta[2], omega[2], delta[2], nut_vel[2] f64            -> 88 bytes total
- SETPOINT (2): state_seq u32, deflection_m[2] f64, sliding[2] f64, reason u8           -> 53 bytes total
- VOLTAGE  (3): state_seq u32, voltage_v[2] f64                                          -> 36 bytes total
- ACK      (4): state_seq u32, setpoint_seq u32, sent u8 (lockstep: controller handled state_seq) -> 25 bytes

Versioning: `VERSION` is bumped on any change of an existing layout; a decoder rejects every version it does not
know. New message types may be added without a bump (old decoders reject them as unknown type). Lengths are exact.
"""
from __future__ import annotations

import math
import struct
from collections import Counter
from dataclasses import dataclass
from enum import IntEnum, StrEnum
from typing import ClassVar, Union

from sea_hil.errors import MalformedPayload

MAGIC = b"SH"
VERSION = 1
SUPPORTED_VERSIONS = frozenset({VERSION})
U32_MAX = 0xFFFF_FFFF
U64_MAX = 0xFFFF_FFFF_FFFF_FFFF
_HEADER = struct.Struct("<2sBBIQ")
HEADER_SIZE = _HEADER.size  # 16


class MsgType(IntEnum):
    STATE = 1
    SETPOINT = 2
    VOLTAGE = 3
    ACK = 4


class TriggerReason(IntEnum):
    """Why the controller transmitted a setpoint."""
    TIME = 0            # periodic (time-triggered baseline)
    ERROR_BOUND = 1     # the ||e|| rule of Eq. 19
    TRACKING_BOUND = 2  # ||X~|| > r
    HEARTBEAT = 3       # maximum inter-event time elapsed
    INITIAL = 4         # first setpoint of a session


class RejectReason(StrEnum):
    LENGTH = "length"
    MAGIC = "magic"
    VERSION = "version"
    TYPE = "type"
    NONFINITE = "nonfinite"
    ENUM = "enum"
    RANGE = "range"


class PayloadRejected(MalformedPayload):
    """A `MalformedPayload` carrying a machine-readable `reason` (for counters)."""

    def __init__(self, reason: RejectReason, detail: str) -> None:
        super().__init__(f"malformed payload ({reason.value}): {detail}")
        self.reason = reason


def _uint(name: str, v: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= hi:
        raise PayloadRejected(RejectReason.RANGE, f"{name}={v!r} is not an integer in [0, {hi}]")
    return v


def _pair(name: str, v: object) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in v)  # type: ignore[union-attr]
    except (TypeError, ValueError) as err:
        raise PayloadRejected(RejectReason.RANGE, f"{name}={v!r} is not a pair of floats") from err
    if not (math.isfinite(a) and math.isfinite(b)):
        raise PayloadRejected(RejectReason.NONFINITE, f"{name}={(a, b)!r} is not finite")
    return (a, b)


class _Payload:
    """Mixin validating the common fields and float pairs (named in `_pairs`) after construction."""
    _pairs: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        _uint("seq", self.seq, U32_MAX)  # type: ignore[attr-defined]
        _uint("t_ns", self.t_ns, U64_MAX)  # type: ignore[attr-defined]
        for name in self._pairs:
            object.__setattr__(self, name, _pair(name, getattr(self, name)))


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
        _uint("sample_t_ns", self.sample_t_ns, U64_MAX)


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
        _uint("state_seq", self.state_seq, U32_MAX)
        try:
            object.__setattr__(self, "reason", TriggerReason(self.reason))
        except ValueError as err:
            raise PayloadRejected(RejectReason.ENUM, f"trigger reason {self.reason!r} is unknown") from err


@dataclass(frozen=True)
class VoltagePayload(_Payload):
    seq: int
    t_ns: int
    state_seq: int
    voltage_v: tuple[float, float]
    _pairs: ClassVar[tuple[str, ...]] = ("voltage_v",)

    def __post_init__(self) -> None:
        super().__post_init__()
        _uint("state_seq", self.state_seq, U32_MAX)


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
        _uint("state_seq", self.state_seq, U32_MAX)
        _uint("setpoint_seq", self.setpoint_seq, U32_MAX)
        object.__setattr__(self, "sent", bool(self.sent))


Payload = Union[StatePayload, SetpointPayload, VoltagePayload, AckPayload]

_BODY = {
    MsgType.STATE: struct.Struct("<Q8d"),
    MsgType.SETPOINT: struct.Struct("<I4dB"),
    MsgType.VOLTAGE: struct.Struct("<I2d"),
    MsgType.ACK: struct.Struct("<IIB"),
}
_TYPE_OF = {StatePayload: MsgType.STATE, SetpointPayload: MsgType.SETPOINT, VoltagePayload: MsgType.VOLTAGE,
            AckPayload: MsgType.ACK}
PAYLOAD_SIZE = {t: HEADER_SIZE + s.size for t, s in _BODY.items()}


def encode(p: Payload) -> bytes:
    """Serialise a (constructor-validated) payload."""
    mtype = _TYPE_OF.get(type(p))
    if mtype is None:
        raise PayloadRejected(RejectReason.TYPE, f"cannot encode {type(p).__name__}")
    head = _HEADER.pack(MAGIC, VERSION, mtype, p.seq, p.t_ns)
    if isinstance(p, StatePayload):
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
    if len(b) < HEADER_SIZE:
        raise PayloadRejected(RejectReason.LENGTH, f"{len(b)} bytes is shorter than the {HEADER_SIZE}-byte header")
    magic, version, mtype, seq, t_ns = _HEADER.unpack_from(b)
    if magic != MAGIC:
        raise PayloadRejected(RejectReason.MAGIC, f"magic {magic!r} != {MAGIC!r}")
    if version not in SUPPORTED_VERSIONS:
        raise PayloadRejected(RejectReason.VERSION, f"version {version} not supported ({sorted(SUPPORTED_VERSIONS)})")
    try:
        mt = MsgType(mtype)
    except ValueError as err:
        raise PayloadRejected(RejectReason.TYPE, f"unknown message type {mtype}") from err
    if len(b) != PAYLOAD_SIZE[mt]:
        raise PayloadRejected(RejectReason.LENGTH, f"{mt.name} must be {PAYLOAD_SIZE[mt]} bytes, got {len(b)}")
    f = _BODY[mt].unpack_from(b, HEADER_SIZE)
    if mt is MsgType.STATE:
        return StatePayload(seq, t_ns, f[0], f[1:3], f[3:5], f[5:7], f[7:9])
    if mt is MsgType.SETPOINT:
        return SetpointPayload(seq, t_ns, f[0], f[1:3], f[3:5], f[5])
    if mt is MsgType.ACK:
        if f[2] > 1:
            raise PayloadRejected(RejectReason.ENUM, f"ack flag {f[2]} is not 0 or 1")
        return AckPayload(seq, t_ns, f[0], f[1], f[2])
    return VoltagePayload(seq, t_ns, f[0], f[1:3])


class PayloadCounters:
    """Accepted / rejected-by-reason counters around `decode` (never raises on bad input)."""

    def __init__(self) -> None:
        self.accepted = 0
        self.rejected: Counter[str] = Counter()
        self.last_error = ""

    def try_decode(self, b: bytes) -> Payload | None:
        """Decode `b`, counting the outcome; None if it was rejected."""
        try:
            p = decode(b)
        except PayloadRejected as err:
            self.rejected[err.reason.value] += 1
            self.last_error = str(err)
            return None
        self.accepted += 1
        return p

    def as_dict(self) -> dict[str, object]:
        return {"accepted": self.accepted, "rejected": dict(self.rejected),
                "rejected_total": sum(self.rejected.values())}


class SeqVerdict(IntEnum):
    NEW = 0        # newer than every accepted message: use it
    DUPLICATE = 1  # already seen
    STALE = 2      # older than the newest accepted (arrived late / reordered): ignore it


class SequenceTracker:
    """Newest-wins tracking of one u32 stream (RFC 1982 serial arithmetic, so seq may wrap).

    `lost` counts skipped sequence numbers; a skipped number that still arrives within the last `window` numbers
    is moved from `lost` to `reordered`. Older arrivals cannot be classified and count as `reordered`. Call
    `restart()` when the sender restarts its sequence (`reset()` also clears the counters).
    """

    def __init__(self, window: int = 64) -> None:
        if window < 1:
            raise ValueError("window must be >= 1")
        self.window = window
        self.reset()

    def reset(self) -> None:
        self.last: int | None = None
        self._seen = 0  # bit i set = (last - i) was seen
        self._span = 0  # how many numbers back from `last` the bitmap covers (<= window; stops at the first)
        self.accepted = self.lost = self.reordered = self.duplicates = 0

    def restart(self) -> None:
        """The sender restarted its sequence: forget the window, keep the counters (the next seq is NEW)."""
        self.last, self._seen, self._span = None, 0, 0

    def feed(self, seq: int) -> SeqVerdict:
        seq = _uint("seq", seq, U32_MAX)
        mask = (1 << self.window) - 1
        if self.last is None:
            self.last, self._seen, self._span, self.accepted = seq, 1, 1, self.accepted + 1
            return SeqVerdict.NEW
        ahead = (seq - self.last) & U32_MAX
        if ahead == 0:
            self.duplicates += 1
            return SeqVerdict.DUPLICATE
        if ahead < 1 << 31:
            self.lost += ahead - 1
            self._seen = ((self._seen << ahead) | 1) & mask if ahead < self.window else 1
            self._span = min(self._span + ahead, self.window)
            self.last = seq
            self.accepted += 1
            return SeqVerdict.NEW
        back = (self.last - seq) & U32_MAX
        if back < self._span:
            if self._seen >> back & 1:
                self.duplicates += 1
                return SeqVerdict.DUPLICATE
            self._seen |= 1 << back
            self.lost -= 1
        self.reordered += 1
        return SeqVerdict.STALE

    def as_dict(self) -> dict[str, int]:
        return {"accepted": self.accepted, "lost": self.lost, "reordered": self.reordered,
                "duplicates": self.duplicates}


# --- wire-size estimate (documented in docs/zenoh-protocol.md) ---------------------------------------------------
# Per express put (no batching): frame header + sn (VLE), push header, mapped key id, QoS ext, put header, payload
# length (VLE). Calibrated with zenoh 1.10.2 through a counting TCP proxy: 88 -> 103, 37 -> 52, 200 -> 216 bytes.
ZENOH_MSG_OVERHEAD = 13
TCP_BATCH_PREFIX = 2      # zenoh's u16 length prefix of each batch on stream links
L3L4 = {"tcp": 20 + 32, "udp": 20 + 8}  # IPv4 + TCP with timestamps option (32) / UDP (8)
ETHERNET = 14 + 4 + 8 + 12  # header + FCS + preamble/SFD + inter-frame gap


def estimate_wire_bytes(payload_len: int, transport: str = "tcp", *, key_len: int | None = None,
                        ethernet: bool = True) -> int:
    """Estimated bytes on the wire for one express (unbatched) zenoh put of `payload_len` bytes.

    `key_len`: if the key expression is not mapped to a numeric id, its length is sent instead of the 2-byte id.
    `ethernet=False` omits the Ethernet framing (e.g. for loopback or IP-level accounting). TCP ACKs in the
    reverse direction are not included.
    """
    if transport not in L3L4:
        raise ValueError(f"transport must be one of {sorted(L3L4)}, got {transport!r}")
    if payload_len < 0:
        raise ValueError("payload_len must be >= 0")
    n = payload_len + ZENOH_MSG_OVERHEAD + (payload_len >= 128)  # payload length VLE takes 2 bytes from 128
    if key_len is not None:
        n += key_len + 1 - 2
    if transport == "tcp":
        n += TCP_BATCH_PREFIX
    return n + L3L4[transport] + (ETHERNET if ethernet else 0)

"""Encode/decode the sea-hil CAN frames. `protocol/sea.dbc` is the single source of truth (docs/can-protocol.md).

`can_id = node_id << 5 | cmd_id`; the DBC holds the node-1 ids and is loaded with frame-id mask 0x1F, so one
definition serves every node. Encoding is strict (out-of-range, NaN, wrong type -> `MalformedFrame`; callers
saturate first, see `SeaCodec.saturate`); decoding checks id, DLC, reserved bits, ranges and enum values.
"""
from __future__ import annotations

import math
import numbers
from collections import OrderedDict, deque
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from importlib import resources
from typing import Any, ClassVar, Iterable, Union

import can
import cantools
from cantools.database import DecodeError, EncodeError

from protocol.errors import ConfigError, MalformedFrame

NODE_ID_MIN, NODE_ID_MAX = 1, 63
CMD_BITS = 5
CMD_MASK = (1 << CMD_BITS) - 1
SEQ_MODULUS = 1 << 8
T_US_MODULUS = 1 << 16
Pair = tuple[float, float]


class DriverState(IntEnum):
    """HEARTBEAT.state (VAL_ table of the DBC)."""
    INIT = 0
    RUNNING = 1
    FAULT = 2
    ESTOP = 3


class ErrorFlags(IntFlag):
    """HEARTBEAT error bits; bit i of byte 1 is DBC signal `err_<name>`."""
    WATCHDOG = 1
    ESTOP = 2
    BAD_FRAME = 4
    OVERRUN = 8
    BUS_ERROR = 16
    SATURATED = 32


_ROLLING = frozenset({"seq", "t_us"})  # counters that wrap; never saturated
_FLAG_SIGNALS = tuple((f, "err_" + (f.name or "").lower()) for f in ErrorFlags)


class _Signals:
    """Mixin: dataclass field <-> DBC signal mapping declared by `FIELDS` (a pair field maps to two signals)."""
    DBC: ClassVar[str]
    FIELDS: ClassVar[tuple[tuple[str, str | tuple[str, str]], ...]] = ()

    def to_signals(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, sig in self.FIELDS:
            value = getattr(self, name)
            if isinstance(sig, tuple):
                out[sig[0]], out[sig[1]] = value  # ValueError/TypeError unless a pair
            else:
                out[sig] = value
        return out

    @classmethod
    def from_signals(cls, node_id: int, s: dict[str, Any]) -> Any:
        kw = {n: (s[g[0]], s[g[1]]) if isinstance(g, tuple) else s[g] for n, g in cls.FIELDS}
        return cls(node_id=node_id, **kw)  # type: ignore[call-arg]


@dataclass(frozen=True)
class EStop(_Signals):
    node_id: int
    DBC: ClassVar[str] = "ESTOP"


@dataclass(frozen=True)
class ClearErrors(_Signals):
    node_id: int
    DBC: ClassVar[str] = "CLEAR_ERRORS"


@dataclass(frozen=True)
class VoltageCmd(_Signals):
    node_id: int
    voltage_v: Pair
    seq: int
    DBC: ClassVar[str] = "VOLTAGE_CMD"
    FIELDS: ClassVar = (("voltage_v", ("voltage1", "voltage2")), ("seq", "seq"))


@dataclass(frozen=True)
class DeflectionSetpoint(_Signals):
    node_id: int
    deflection_m: Pair
    seq: int
    DBC: ClassVar[str] = "DEFLECTION_SETPOINT"
    FIELDS: ClassVar = (("deflection_m", ("vx1", "vx2")), ("seq", "seq"))


@dataclass(frozen=True)
class Heartbeat(_Signals):
    node_id: int
    state: DriverState
    flags: ErrorFlags
    rejected_frames: int
    overruns: int
    seq: int
    DBC: ClassVar[str] = "HEARTBEAT"
    FIELDS: ClassVar = (("state", "state"), ("rejected_frames", "rejected_frames"), ("overruns", "overruns"),
                        ("seq", "seq"))

    def to_signals(self) -> dict[str, Any]:
        flags = int(self.flags)
        if flags & ~sum(int(f) for f, _ in _FLAG_SIGNALS):
            raise ValueError(f"unknown error flag bits in 0x{flags:X}")
        return {**super().to_signals(), "state": int(DriverState(self.state)),
                **{sig: int(bool(flags & f)) for f, sig in _FLAG_SIGNALS}}

    @classmethod
    def from_signals(cls, node_id: int, s: dict[str, Any]) -> Heartbeat:
        flags = ErrorFlags(sum(int(f) for f, sig in _FLAG_SIGNALS if s[sig]))
        return cls(node_id, DriverState(s["state"]), flags, s["rejected_frames"], s["overruns"], s["seq"])


@dataclass(frozen=True)
class FeedbackAngle(_Signals):
    node_id: int
    seq: int
    t_us: int
    theta_rad: Pair
    DBC: ClassVar[str] = "FEEDBACK_ANGLE"
    FIELDS: ClassVar = (("seq", "seq"), ("t_us", "t_us"), ("theta_rad", ("theta1", "theta2")))


@dataclass(frozen=True)
class FeedbackDeflection(_Signals):
    node_id: int
    seq: int
    delta_m: Pair
    DBC: ClassVar[str] = "FEEDBACK_DEFLECTION"
    FIELDS: ClassVar = (("seq", "seq"), ("delta_m", ("delta1", "delta2")))


@dataclass(frozen=True)
class FeedbackVelocity(_Signals):
    node_id: int
    seq: int
    omega_rad_s: Pair
    nut_vel_m_s: Pair
    DBC: ClassVar[str] = "FEEDBACK_VELOCITY"
    FIELDS: ClassVar = (("seq", "seq"), ("omega_rad_s", ("omega1", "omega2")),
                        ("nut_vel_m_s", ("nut_vel1", "nut_vel2")))


@dataclass(frozen=True)
class Feedback:
    """One driver sample, carried by three frames sharing `seq`. `t_us` is the rolling 16-bit value (`unwrap_us`)."""
    node_id: int
    seq: int
    t_us: int
    theta_rad: Pair
    omega_rad_s: Pair
    delta_m: Pair
    nut_vel_m_s: Pair

    def parts(self) -> tuple[FeedbackAngle, FeedbackDeflection, FeedbackVelocity]:
        n, q = self.node_id, self.seq
        return (FeedbackAngle(n, q, self.t_us, self.theta_rad), FeedbackDeflection(n, q, self.delta_m),
                FeedbackVelocity(n, q, self.omega_rad_s, self.nut_vel_m_s))

    @classmethod
    def from_parts(cls, a: FeedbackAngle, d: FeedbackDeflection, v: FeedbackVelocity) -> Feedback:
        return cls(a.node_id, a.seq, a.t_us, a.theta_rad, v.omega_rad_s, d.delta_m, v.nut_vel_m_s)


Frame = Union[EStop, ClearErrors, VoltageCmd, DeflectionSetpoint, Heartbeat,
              FeedbackAngle, FeedbackDeflection, FeedbackVelocity]
FRAME_TYPES: tuple[type, ...] = (EStop, ClearErrors, VoltageCmd, DeflectionSetpoint, Heartbeat,
                                 FeedbackAngle, FeedbackDeflection, FeedbackVelocity)
FEEDBACK_PARTS: tuple[type, ...] = (FeedbackAngle, FeedbackDeflection, FeedbackVelocity)


def can_id_of(node_id: int, cmd_id: int) -> int:
    """11-bit identifier of command `cmd_id` for node `node_id`."""
    return check_node_id(node_id) << CMD_BITS | (cmd_id & CMD_MASK)


def check_node_id(node_id: Any) -> int:
    if not isinstance(node_id, numbers.Integral) or not NODE_ID_MIN <= int(node_id) <= NODE_ID_MAX:
        raise MalformedFrame(f"node id {node_id!r} not in {NODE_ID_MIN}..{NODE_ID_MAX}")
    return int(node_id)


def load_database() -> cantools.database.can.Database:
    """Parse the packaged DBC (frame ids masked to the command bits)."""
    text = resources.files("protocol").joinpath("sea.dbc").read_text(encoding="utf-8")
    return cantools.database.load_string(text, database_format="dbc", frame_id_mask=CMD_MASK, strict=True)


@dataclass(frozen=True)
class _Sig:
    name: str
    minimum: float
    maximum: float
    tol: float
    is_int: bool
    choices: frozenset[int] | None


@dataclass(frozen=True)
class _Layout:
    cls: type
    message: Any
    cmd_id: int
    dlc: int
    used_mask: int
    sigs: tuple[_Sig, ...]


def _layout(db: Any, cls: type) -> _Layout:
    msg = db.get_message_by_name(cls.DBC)
    sigs, used = [], 0
    for s in msg.signals:
        if s.byte_order != "little_endian" or s.minimum is None or s.maximum is None:
            raise ConfigError(f"sea.dbc: signal {msg.name}.{s.name} must be little-endian with min/max")
        used |= ((1 << s.length) - 1) << s.start
        is_int = s.scale == 1 and s.offset == 0 and not s.is_float
        choices = frozenset(int(k) for k in s.choices) if s.choices else None
        sigs.append(_Sig(s.name, s.minimum, s.maximum, abs(s.scale) * 1e-6, is_int, choices))
    return _Layout(cls, msg, msg.frame_id & CMD_MASK, msg.length, used, tuple(sigs))


class SeaCodec:
    """Dataclass <-> `can.Message` for the sea-hil protocol; `node_ids` restricts which nodes decode accepts."""

    def __init__(self, node_ids: Iterable[int] | None = None) -> None:
        self._db = load_database()
        self._node_ids = None if node_ids is None else frozenset(check_node_id(n) for n in node_ids)
        layouts = [_layout(self._db, cls) for cls in FRAME_TYPES]
        self._by_cls = {lay.cls: lay for lay in layouts}
        self._by_cmd = {lay.cmd_id: lay for lay in layouts}

    def encode(self, obj: Frame) -> can.Message:
        lay = self._layout_of(type(obj))
        node_id = check_node_id(obj.node_id)
        try:
            values = obj.to_signals()
            for s in lay.sigs:
                _check_encodable(s, values[s.name])
            data = self._db.encode_message(lay.message.name, values, strict=True)
        except (EncodeError, TypeError, ValueError, OverflowError, KeyError) as err:
            raise MalformedFrame(f"cannot encode {lay.message.name} for node {node_id}: {err}") from None
        return can.Message(arbitration_id=node_id << CMD_BITS | lay.cmd_id, data=data, is_extended_id=False)

    def encode_feedback(self, fb: Feedback) -> list[can.Message]:
        return [self.encode(p) for p in fb.parts()]

    def decode(self, msg: can.Message) -> Frame:
        """Decoded frame, or `MalformedFrame` saying why it is not acceptable."""
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or msg.is_fd:
            kind = ("error" if msg.is_error_frame else "remote" if msg.is_remote_frame
                    else "extended-id" if msg.is_extended_id else "CAN FD")
            raise MalformedFrame(f"{kind} frame (id 0x{msg.arbitration_id:X}) not accepted")
        can_id = msg.arbitration_id
        node_id, lay = can_id >> CMD_BITS, self._by_cmd.get(can_id & CMD_MASK)
        if not 0 <= can_id <= 0x7FF or lay is None or node_id < NODE_ID_MIN:
            raise MalformedFrame(f"unknown CAN id 0x{can_id:03X}")
        if self._node_ids is not None and node_id not in self._node_ids:
            raise MalformedFrame(f"{lay.message.name} for node {node_id}, which is not served")
        data = bytes(msg.data or b"")
        if len(data) != lay.dlc or msg.dlc != len(data):
            raise MalformedFrame(f"{lay.message.name} node {node_id}: DLC {msg.dlc} with {len(data)} bytes, "
                                 f"expected {lay.dlc}")
        if int.from_bytes(data, "little") & ~lay.used_mask:
            raise MalformedFrame(f"{lay.message.name} node {node_id}: reserved bits set in {data.hex()}")
        try:
            raw = lay.message.decode(data, decode_choices=False, allow_excess=False)
        except (DecodeError, ValueError) as err:
            raise MalformedFrame(f"{lay.message.name} node {node_id}: {err}") from None
        values = {s.name: _checked(lay.message.name, s, raw[s.name]) for s in lay.sigs}
        return lay.cls.from_signals(node_id, values)

    def saturate(self, obj: Any) -> tuple[Any, bool]:
        """Copy of `obj` with every physical value and counter clamped to its DBC range (not seq/t_us, enums, NaN);
        the flag says whether anything changed."""
        if isinstance(obj, Feedback):
            res = [self.saturate(p) for p in obj.parts()]
            return Feedback.from_parts(*(p for p, _ in res)), any(c for _, c in res)
        lay = self._layout_of(type(obj))
        values, changed = obj.to_signals(), False
        for s in lay.sigs:
            v = values[s.name]
            if s.name in _ROLLING or s.choices is not None or not isinstance(v, numbers.Real) or math.isnan(v):
                continue
            c = min(max(v, s.minimum), s.maximum)
            if c != v:
                values[s.name], changed = (int(c) if s.is_int else float(c)), True
        return (lay.cls.from_signals(obj.node_id, values) if changed else obj), changed

    def _layout_of(self, cls: type) -> _Layout:
        lay = self._by_cls.get(cls)
        if lay is None:
            raise MalformedFrame(f"{cls.__name__} is not a sea-hil CAN frame type")
        return lay


def _check_encodable(s: _Sig, v: Any) -> None:
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f"signal {s.name}: {v!r} is not a number")
    if s.is_int and not isinstance(v, numbers.Integral):
        raise TypeError(f"signal {s.name}: {v!r} is not an integer")
    if not math.isfinite(v):
        raise ValueError(f"signal {s.name}: {v!r} is not finite")


def _checked(name: str, s: _Sig, v: Any) -> Any:
    if not math.isfinite(v):
        raise MalformedFrame(f"{name}.{s.name}: non-finite value {v!r}")
    if s.choices is not None and v not in s.choices:
        raise MalformedFrame(f"{name}.{s.name}: bad enum value {v!r}, allowed {sorted(s.choices)}")
    if not s.minimum - s.tol <= v <= s.maximum + s.tol:
        raise MalformedFrame(f"{name}.{s.name}: {v!r} outside [{s.minimum}, {s.maximum}]")
    return int(v) if s.is_int else min(max(float(v), s.minimum), s.maximum)


def unwrap_us(prev_full_us: int, wrapped: int) -> int:
    """The full time whose low 16 bits are `wrapped` nearest to `prev_full_us` (valid for |gap| < 32.768 ms)."""
    if not isinstance(wrapped, numbers.Integral) or not 0 <= wrapped < T_US_MODULUS:
        raise MalformedFrame(f"t_us {wrapped!r} not in 0..{T_US_MODULUS - 1}")
    half = T_US_MODULUS // 2
    return prev_full_us + (wrapped - prev_full_us + half) % T_US_MODULUS - half


def seq_gap(prev_seq: int, seq: int) -> int:
    """Forward distance prev_seq -> seq of the rolling 8-bit counters (1 = consecutive, 0 = repeat)."""
    return (seq - prev_seq) % SEQ_MODULUS


class FeedbackAssembler:
    """Pairs the three feedback frames of one (node, seq) into a `Feedback`.

    A sample is dropped (`incomplete` += 1) when a later sample completes first or more than `max_pending`
    samples are open; a frame of an already closed sample or a duplicate part is dropped (`stale` += 1).
    """

    def __init__(self, max_pending: int = 4) -> None:
        self._max_pending = max(1, max_pending)
        self._pending: dict[int, OrderedDict[int, dict[type, Any]]] = {}
        self._closed: dict[int, deque[int]] = {}
        self.incomplete = 0
        self.stale = 0

    def push(self, part: FeedbackAngle | FeedbackDeflection | FeedbackVelocity) -> Feedback | None:
        if not isinstance(part, FEEDBACK_PARTS):
            raise TypeError(f"FeedbackAssembler.push needs a feedback frame, got {type(part).__name__}")
        node, seq = part.node_id, part.seq
        pending = self._pending.setdefault(node, OrderedDict())
        closed = self._closed.setdefault(node, deque(maxlen=2 * self._max_pending))
        parts = pending.get(seq, {})
        if seq in closed or type(part) in parts:
            self.stale += 1
            return None
        parts[type(part)] = part
        pending[seq] = parts
        if len(parts) == len(FEEDBACK_PARTS):
            while True:
                old, _ = pending.popitem(last=False)
                closed.append(old)
                if old == seq:
                    break
                self.incomplete += 1
            return Feedback.from_parts(parts[FeedbackAngle], parts[FeedbackDeflection], parts[FeedbackVelocity])
        while len(pending) > self._max_pending:
            closed.append(pending.popitem(last=False)[0])
            self.incomplete += 1
        return None

"""Encode/decode the sea-hil CAN frames. `protocol/sea.dbc` is the single source of truth (docs/can-protocol.md).

`can_id = node_id << 5 | cmd_id`; the DBC holds the node-1 ids and is loaded with frame-id mask 0x1F, so one
definition serves every node. Two profiles (`fd`): classic CAN (VOLTAGE_CMD, three feedback frames per sample) and
CAN FD (VOLTAGE_CMD_FD and one FEEDBACK_FD frame per sample, sent with the bit rate switch; ESTOP, CLEAR_ERRORS,
DEFLECTION_SETPOINT and HEARTBEAT stay classic frames on the FD bus); `fd=None` decodes both (recorders, monitors)
and encodes classic. A frame's FD flag must match its DBC message. Encoding is strict (out-of-range, NaN, wrong type -> `MalformedFrame`; callers
saturate first, see `SeaCodec.saturate`); decoding checks id, DLC, reserved bits, ranges and enum values.
Packing and unpacking run on precompiled frame plans built from the DBC's cantools messages
(`sea_hil.protocol.frame_plan`: byte for byte cantools strict, tests/test_frame_plan.py), not on cantools per frame.
The frame types (`sea_hil.protocol.can_frames`) and feedback assembly (`sea_hil.protocol.can_assembly`) are re-exported here.
"""
from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Any

import can
import cantools
from cantools.database import EncodeError

from sea_hil.errors import ConfigError, MalformedFrame
from sea_hil.protocol.can_frames import (
    CMD_BITS,
    CMD_MASK,
    FEEDBACK_PARTS,
    NODE_ID_MAX,
    NODE_ID_MIN,
    ROLLING,
    Feedback,
    Frame,
    SignalBinding,
    binding_of,
    check_node_id,
    profile_messages,
)
from sea_hil.protocol.frame_plan import FramePlan

__all__ = ["SeaCodec", "load_database"]


@functools.cache
def load_database() -> cantools.database.can.Database:
    """The packaged DBC (frame ids masked to the command bits), parsed once per process (~25 ms) and shared: read
    only."""
    text = resources.files("sea_hil.protocol").joinpath("sea.dbc").read_text(encoding="utf-8")
    db = cantools.database.load_string(text, database_format="dbc", frame_id_mask=CMD_MASK, strict=True)
    assert isinstance(db, cantools.database.can.Database)   # a DBC is a CAN database
    return db


@dataclass(frozen=True)
class _Sig:
    name: str
    minimum: float
    maximum: float
    tol: float
    is_int: bool
    choices: frozenset[int] | None

    @property
    def clampable(self) -> bool:
        """`saturate` clamps it: not a rolling counter, not an enum."""
        return self.name not in ROLLING and self.choices is None


@dataclass(frozen=True)
class _Layout:
    cls: type[Frame]
    message: Any
    cmd_id: int
    dlc: int
    used_mask: int
    sigs: tuple[_Sig, ...]
    is_fd: bool
    # per signal (sig, name, min, max, is_int, clampable, min - tol, max + tol, plain): the hot paths' precomputed
    # view of `sigs`; `plain` = no enum, so a finite in-range value needs no further check
    plan: tuple[tuple[Any, ...], ...]
    frame: FramePlan                 # the precompiled pack/unpack of `message` (sea_hil.protocol.frame_plan)
    binding: SignalBinding | None = None   # fields <-> the plan's value tuple (None: through the signal dicts)


def _layout(cls: type[Frame], name: str) -> _Layout:
    """The immutable layout of message `name` for frame type `cls` (its precompiled frame plan): built once per
    process and shared by every codec (building one costs ~1 ms, a codec ~40 ms: one per edge core, per offline
    sweep point)."""
    key: Any = cls      # mypy takes a union of frame types for unhashable (functools.cache's Hashable arguments)
    return _built_layout(key, name)


@functools.cache
def _built_layout(cls: type[Frame], name: str) -> _Layout:
    msg = load_database().get_message_by_name(name)
    sigs, used = [], 0
    for s in msg.signals:
        if s.byte_order != "little_endian" or s.minimum is None or s.maximum is None:
            raise ConfigError(f"sea.dbc: signal {msg.name}.{s.name} must be little-endian with min/max")
        used |= ((1 << s.length) - 1) << s.start
        is_int = s.scale == 1 and s.offset == 0 and not s.is_float
        choices = frozenset(int(k) for k in s.choices) if s.choices else None
        sigs.append(_Sig(s.name, s.minimum, s.maximum, abs(s.scale) * 1e-6, is_int, choices))
    frame = FramePlan.of(msg)
    by_name = {sig.name: sig for sig in sigs}
    sigs = [by_name[n] for n in frame.names]   # the plan's order (the DBC's)
    plan = tuple((s, s.name, s.minimum, s.maximum, s.is_int, s.clampable, s.minimum - s.tol, s.maximum + s.tol,
                  s.choices is None) for s in sigs)
    return _Layout(cls, msg, msg.frame_id & CMD_MASK, msg.length, used, tuple(sigs), bool(msg.is_fd), plan,
                   frame, binding_of(cls, frame.names))


# the sample's signals in one flat list (FEEDBACK_FD's names: every classic part's signal is one of them)
_FEEDBACK_NAMES = tuple(sig for _, g in Feedback.FIELDS for sig in (g if isinstance(g, tuple) else (g,)))
_FEEDBACK_BINDING = SignalBinding(Feedback, _FEEDBACK_NAMES)


@functools.cache
def _parts_plan() -> tuple[tuple[_Layout, tuple[int, ...]], ...]:
    """Per classic feedback part (angle, joint 1, joint 2): its layout and where its plan's signals sit in
    `_FEEDBACK_BINDING.values(fb)`."""
    layouts = [_layout(cls, name) for cls, name in profile_messages(False).items() if cls in FEEDBACK_PARTS]
    return tuple((lay, tuple(_FEEDBACK_NAMES.index(n) for n in lay.frame.names)) for lay in layouts)


class SeaCodec:
    """Dataclass <-> `can.Message` for the sea-hil protocol; `node_ids` restricts which nodes decode accepts, `fd`
    picks the profile (None: decode both, encode classic), `bitrate_switch` the BRS bit of the FD frames sent."""

    def __init__(self, node_ids: Iterable[int] | None = None, *, fd: bool | None = False,
                 bitrate_switch: bool = True) -> None:
        self._node_ids = None if node_ids is None else frozenset(check_node_id(n) for n in node_ids)
        self.fd, self.bitrate_switch = fd, bitrate_switch
        profiles = (False, True) if fd is None else (fd,)
        layouts = {p: [_layout(cls, name) for cls, name in profile_messages(p).items()] for p in profiles}
        self._by_cls = {lay.cls: lay for lay in layouts[bool(fd)]}
        self._by_cmd = {lay.cmd_id: lay for p in profiles for lay in layouts[p]}
        self._other = {lay.cmd_id: lay.message.name for p in (False, True) if p not in profiles
                       for lay in (_layout(c, n) for c, n in profile_messages(p).items())}

    @classmethod
    def for_bus(cls, can_cfg: Any, node_ids: Iterable[int] | None = None) -> SeaCodec:
        """The codec of the profile `[can]` configures (`fd`; bit rate switch when the data rate is higher)."""
        return cls(node_ids, fd=can_cfg.fd, bitrate_switch=can_cfg.data_bitrate_bps > can_cfg.bitrate_bps)

    def encode(self, obj: Frame, *, saturate: bool = False) -> can.Message:
        """Strict encoding (`MalformedFrame` on anything out of range); `saturate=True` clamps first, like
        `encode(saturate(obj)[0])` without the intermediate object."""
        lay = self._layout_of(type(obj))
        node_id = obj.node_id
        if type(node_id) is not int or not NODE_ID_MIN <= node_id <= NODE_ID_MAX:  # fast path for plain ints
            node_id = check_node_id(node_id)
        data = None
        if lay.binding is not None:   # the common case: plain numbers in range, packed by the precompiled plan
            try:
                data = lay.frame.pack_plain(lay.binding.values(obj))
            except (TypeError, ValueError):
                data = None           # e.g. not a pair: the general path below says what is wrong
        if data is None:
            data = self._encode_general(lay, obj, node_id, saturate)
        # immutable bytes as `data`: python-can's virtual bus deep-copies the message once per receiver, and a
        # deepcopy of bytes is free (of a bytearray it is not)
        return new_message(node_id << CMD_BITS | lay.cmd_id, data, lay.is_fd, lay.is_fd and self.bitrate_switch)

    def _encode_general(self, lay: _Layout, obj: Frame, node_id: int, saturate: bool) -> bytes:
        """Check (and with `saturate` clamp) every signal, then pack: strict like cantools (tests/test_frame_plan)."""
        try:
            values = obj.to_signals()
            for s, name, lo, hi, is_int, clampable, _, _, _ in lay.plan:
                v = values[name]
                t = type(v)
                if (t is int or t is float and not is_int) and lo <= v <= hi:
                    continue    # a finite number of the right kind in range, nothing to do
                if saturate and clampable:
                    v = _clamped(s, v, values)
                _check_encodable(s, v)
            return lay.frame.encode([values[n] for n in lay.frame.names])
        except (EncodeError, TypeError, ValueError, OverflowError, KeyError, MalformedFrame) as err:
            raise MalformedFrame(f"cannot encode {lay.message.name} for node {node_id}: {err}") from err

    def encode_feedback(self, fb: Feedback, *, saturate: bool = False) -> list[can.Message]:
        """The frames of one sample: one FEEDBACK_FD (CAN FD profile) or the three classic parts. Classic: the
        parts' values are taken from `fb` at once (`_parts_plan`: each part's signals are the sample's), packed by
        the parts' plans; anything not plain (out of range, not a number) goes through `encode` of `fb.parts()`."""
        if Feedback in self._by_cls:
            return [self.encode(fb, saturate=saturate)]
        node_id = fb.node_id
        if type(node_id) is int and NODE_ID_MIN <= node_id <= NODE_ID_MAX:
            try:
                values = _FEEDBACK_BINDING.values(fb)
                out = []
                for lay, index in _parts_plan():
                    data = lay.frame.pack_plain([values[i] for i in index])
                    if data is None:
                        break
                    out.append(new_message(node_id << CMD_BITS | lay.cmd_id, data, False, False))
                else:
                    return out
            except (TypeError, ValueError):
                pass   # e.g. not a pair: the general path says what is wrong
        return [self.encode(p, saturate=saturate) for p in fb.parts()]

    def decode(self, msg: can.Message) -> Frame:
        """Decoded frame, or `MalformedFrame` saying why it is not acceptable."""
        return self.decode_raw(msg.arbitration_id, bytes(msg.data or b""), msg.dlc, is_extended=msg.is_extended_id,
                               is_error=msg.is_error_frame, is_remote=msg.is_remote_frame, is_fd=msg.is_fd)

    def decode_raw(self, can_id: int, data: bytes, dlc: int, *, is_extended: bool = False, is_error: bool = False,
                   is_remote: bool = False, is_fd: bool = False) -> Frame:
        """`decode` on the parts of a frame (as recorded); `MalformedFrame` saying why it is not acceptable."""
        if is_error or is_remote or is_extended:
            kind = "error" if is_error else "remote" if is_remote else "extended-id"
            raise MalformedFrame(f"{kind} frame (id 0x{can_id:X}) not accepted")
        node_id, lay = can_id >> CMD_BITS, self._by_cmd.get(can_id & CMD_MASK)
        if not 0 <= can_id <= 0x7FF or lay is None or node_id < NODE_ID_MIN:
            other = self._other.get(can_id & CMD_MASK) if 0 <= can_id <= 0x7FF else None
            if other is not None:
                raise MalformedFrame(f"{other} (id 0x{can_id:03X}) belongs to the "
                                     f"{'classic' if self.fd else 'CAN FD'} profile; this node runs "
                                     f"{'CAN FD' if self.fd else 'classic CAN'} ([can] fd)")
            raise MalformedFrame(f"unknown CAN id 0x{can_id:03X}")
        if is_fd != lay.is_fd:
            raise MalformedFrame(f"{'CAN FD' if is_fd else 'classic'} frame (id 0x{can_id:03X}) not accepted: "
                                 f"{lay.message.name} is a {'CAN FD' if lay.is_fd else 'classic'} frame")
        if self._node_ids is not None and node_id not in self._node_ids:
            raise MalformedFrame(f"{lay.message.name} for node {node_id}, which is not served")
        if len(data) != lay.dlc or dlc != len(data):
            raise MalformedFrame(f"{lay.message.name} node {node_id}: DLC {dlc} with {len(data)} bytes, "
                                 f"expected {lay.dlc}")
        if int.from_bytes(data, "little") & ~lay.used_mask:
            raise MalformedFrame(f"{lay.message.name} node {node_id}: reserved bits set in {data.hex()}")
        # = cantools decode (tests/test_frame_plan), all values in range
        vals: Sequence[Any] | None = lay.frame.unpack_plain(data)
        if vals is None:                      # some value outside its DBC range: clamp within tolerance, or reject
            vals = [(int(v) if is_int else min(max(float(v), lo), hi))
                    if plain and lo_tol <= v <= hi_tol   # finite (NaN and inf fail the comparison) and in range
                    else _checked(lay.message.name, s, v)
                    for (s, name, lo, hi, is_int, _, lo_tol, hi_tol, plain), v in zip(lay.plan, lay.frame.unpack(data), strict=True)]
        if lay.binding is not None:
            return lay.binding.build(node_id, vals)
        return lay.cls.from_signals(node_id, dict(zip(lay.frame.names, vals, strict=True)))

    def saturate(self, obj: Any) -> tuple[Any, bool]:
        """Copy of `obj` with every physical value and counter clamped to its DBC range (not seq/t_us, enums, NaN);
        the flag says whether anything changed."""
        if isinstance(obj, Feedback) and Feedback not in self._by_cls:
            res = [self.saturate(p) for p in obj.parts()]
            return Feedback.from_parts(*(p for p, _ in res)), any(c for _, c in res)
        lay = self._layout_of(type(obj))
        values = obj.to_signals()
        changed = _clamp(lay, values)
        return (lay.cls.from_signals(obj.node_id, values) if changed else obj), changed

    def _layout_of(self, cls: type[Frame]) -> _Layout:
        lay = self._by_cls.get(cls)
        if lay is None:
            raise MalformedFrame(f"{cls.__name__} is not a sea-hil CAN frame type")
        return lay


_new_message = object.__new__


def new_message(can_id: int, data: bytes, is_fd: bool, bitrate_switch: bool) -> can.Message:
    """`can.Message(arbitration_id=can_id, data=data, is_extended_id=False, is_fd=is_fd,
    bitrate_switch=bitrate_switch)` with `data` kept as the given bytes, slot by slot (the constructor's keyword
    handling cost ~4 us, this ~1 us; tests/test_hotpath.py checks every slot against the constructor)."""
    m = _new_message(can.Message)
    m.timestamp = 0.0
    m.arbitration_id = can_id
    m.is_extended_id = m.is_remote_frame = m.is_error_frame = m.error_state_indicator = False
    m.channel = None
    m.is_fd = is_fd
    m.is_rx = True
    m.bitrate_switch = bitrate_switch
    m.data = data  # type: ignore[assignment]
    m.dlc = len(data)
    return m


def _clamp(lay: _Layout, values: dict[str, Any]) -> bool:
    """Clamp `values` in place to the DBC ranges (not seq/t_us, enums, non-numbers, NaN); True if any changed."""
    changed = False
    for s in lay.sigs:
        if s.clampable:
            v = values[s.name]
            changed = _clamped(s, v, values) is not v or changed
    return changed


def _clamped(s: _Sig, v: Any, values: dict[str, Any]) -> Any:
    """v clamped to the range of signal s (stored in `values` if it changed); non-numbers and NaN unchanged."""
    if not _is_real(v) or math.isnan(v):
        return v
    c = min(max(v, s.minimum), s.maximum)
    if c != v:
        v = values[s.name] = int(c) if s.is_int else float(c)
    return v


def _is_real(v: Any) -> bool:
    t = type(v)
    return t is float or t is int or isinstance(v, numbers.Real)  # exact types first: ABC checks are slow


def _check_encodable(s: _Sig, v: Any) -> None:
    t = type(v)
    if t is float and not s.is_int or t is int:
        if t is float and not math.isfinite(v):
            raise ValueError(f"signal {s.name}: {v!r} is not finite")
        return
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


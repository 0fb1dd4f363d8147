"""The sea-hil CAN frame types (one frozen dataclass per DBC message), ids and rolling-counter constants.

`can_id = node_id << 5 | cmd_id`. Each frame class names its DBC message per profile (`DBC`: classic CAN, `DBC_FD`:
the CAN FD profile; "" = not in that profile) and maps its fields to DBC signals (`FIELDS`); encoding/decoding lives
in `sea_hil.protocol.can_codec`, pairing the classic feedback frames in `sea_hil.protocol.can_assembly`. A `Feedback`
sample is three classic frames (`parts()`) or one CAN FD frame (FEEDBACK_FD); a `VoltageCmd` is VOLTAGE_CMD or
VOLTAGE_CMD_FD.
"""
from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import Any, ClassVar, Self

from sea_hil.errors import MalformedFrame

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
    """HEARTBEAT error bits; bit i is DBC signal `err_<name>` at frame bit 8 + i (the 16-bit flag field)."""
    WATCHDOG = 1
    ESTOP = 2
    BAD_FRAME = 4
    OVERRUN = 8
    BUS_ERROR = 16
    SATURATED = 32
    POSITION_LIMIT = 64     # a joint left its soft position range (drive faulted)
    VELOCITY_LIMIT = 128    # a joint exceeded its velocity limit (drive faulted)
    FORCE_LIMIT = 256       # an SEA spring force exceeded its limit (drive faulted)


LIMIT_FLAGS = ErrorFlags.POSITION_LIMIT | ErrorFlags.VELOCITY_LIMIT | ErrorFlags.FORCE_LIMIT  # soft-limit faults


ROLLING = frozenset({"seq", "t_us"})  # counters that wrap; never saturated
_FLAG_SIGNALS = tuple((f, "err_" + (f.name or "").lower()) for f in ErrorFlags)


class _Signals:
    """Mixin: dataclass field <-> DBC signal mapping declared by `FIELDS` (a pair field maps to two signals)."""
    DBC: ClassVar[str]
    DBC_FD: ClassVar[str | None] = None   # None: the same message as `DBC` in the CAN FD profile
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
    def from_signals(cls, node_id: int, s: dict[str, Any]) -> Self:
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
    DBC_FD: ClassVar[str | None] = "VOLTAGE_CMD_FD"
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
    DBC_FD: ClassVar[str | None] = ""
    FIELDS: ClassVar = (("seq", "seq"), ("t_us", "t_us"), ("theta_rad", ("theta1", "theta2")))


@dataclass(frozen=True)
class _FeedbackJoint(_Signals):
    """Feedback of one SEA (one joint): joint velocity, spring deflection, nut velocity."""
    DBC_FD: ClassVar[str | None] = ""
    node_id: int
    seq: int
    omega_rad_s: float
    delta_m: float
    nut_vel_m_s: float


@dataclass(frozen=True)
class FeedbackJoint1(_FeedbackJoint):
    DBC: ClassVar[str] = "FEEDBACK_JOINT1"
    FIELDS: ClassVar = (("seq", "seq"), ("omega_rad_s", "omega1"), ("delta_m", "delta1"),
                        ("nut_vel_m_s", "nut_vel1"))


@dataclass(frozen=True)
class FeedbackJoint2(_FeedbackJoint):
    DBC: ClassVar[str] = "FEEDBACK_JOINT2"
    FIELDS: ClassVar = (("seq", "seq"), ("omega_rad_s", "omega2"), ("delta_m", "delta2"),
                        ("nut_vel_m_s", "nut_vel2"))


@dataclass(frozen=True)
class Feedback(_Signals):
    """One driver sample: three classic frames sharing `seq` (`parts()`), or one FEEDBACK_FD frame. `t_us` is the
    rolling 16-bit value (`unwrap_us`)."""
    node_id: int
    seq: int
    t_us: int
    theta_rad: Pair
    omega_rad_s: Pair
    delta_m: Pair
    nut_vel_m_s: Pair
    DBC: ClassVar[str] = ""
    DBC_FD: ClassVar[str | None] = "FEEDBACK_FD"
    FIELDS: ClassVar = (("seq", "seq"), ("t_us", "t_us"), ("theta_rad", ("theta1", "theta2")),
                        ("omega_rad_s", ("omega1", "omega2")), ("delta_m", ("delta1", "delta2")),
                        ("nut_vel_m_s", ("nut_vel1", "nut_vel2")))

    def parts(self) -> tuple[FeedbackAngle, FeedbackJoint1, FeedbackJoint2]:
        n, q, w, d, v = self.node_id, self.seq, self.omega_rad_s, self.delta_m, self.nut_vel_m_s
        return (FeedbackAngle(n, q, self.t_us, self.theta_rad), FeedbackJoint1(n, q, w[0], d[0], v[0]),
                FeedbackJoint2(n, q, w[1], d[1], v[1]))

    @classmethod
    def from_parts(cls, a: FeedbackAngle, j1: FeedbackJoint1, j2: FeedbackJoint2) -> Feedback:
        return cls(a.node_id, a.seq, a.t_us, a.theta_rad, (j1.omega_rad_s, j2.omega_rad_s), (j1.delta_m, j2.delta_m),
                   (j1.nut_vel_m_s, j2.nut_vel_m_s))


Frame = (EStop | ClearErrors | VoltageCmd | DeflectionSetpoint | Heartbeat
         | FeedbackAngle | FeedbackJoint1 | FeedbackJoint2 | Feedback)
FRAME_TYPES: tuple[type[Frame], ...] = (EStop, ClearErrors, VoltageCmd, DeflectionSetpoint, Heartbeat,
                                 FeedbackAngle, FeedbackJoint1, FeedbackJoint2, Feedback)


def profile_messages(fd: bool) -> dict[type[Frame], str]:
    """Frame type -> its DBC message in the classic (`fd` False) or the CAN FD profile."""
    out: dict[type[Frame], str] = {}
    for cls in FRAME_TYPES:
        name = cls.DBC if not fd else cls.DBC if cls.DBC_FD is None else cls.DBC_FD
        if name:
            out[cls] = name
    return out
FEEDBACK_PARTS: tuple[type[FeedbackAngle], type[FeedbackJoint1], type[FeedbackJoint2]] = (FeedbackAngle, FeedbackJoint1,
                                                                                           FeedbackJoint2)


class SignalBinding:
    """A frame type's fields bound to positions in a signal tuple (a frame plan's `names` order), written out once as
    straight-line code, so the hot paths go object -> values -> object without the `to_signals` / `from_signals`
    dicts; the same mapping (`FIELDS`). `values(obj)` raises ValueError/TypeError unless each pair field is a pair."""

    def __init__(self, cls: type[Frame], names: tuple[str, ...]) -> None:
        index = {n: i for i, n in enumerate(names)}
        flat = [sig for _, g in cls.FIELDS for sig in (g if isinstance(g, tuple) else (g,))]   # FIELDS order
        if sorted(flat) != sorted(names):
            raise ValueError(f"{cls.__name__}: FIELDS do not cover the signals {names}")
        lines, exprs = ["def values(o):"], []
        for i, (f, g) in enumerate(cls.FIELDS):
            if isinstance(g, tuple):
                lines.append(f"    p{i}a, p{i}b = o.{f}")
                exprs += [f"p{i}a", f"p{i}b"]
            else:
                exprs.append(f"o.{f}")
        lines.append(f"    return [{', '.join(exprs[flat.index(n)] for n in names)}]")
        specs = {f: (f"(v[{index[g[0]]}], v[{index[g[1]]}])" if isinstance(g, tuple) else f"v[{index[g]}]")
                 for f, g in cls.FIELDS}
        args = "".join(f", {specs[fl.name]}" for fl in dataclasses.fields(cls)[1:])   # dataclass order
        lines += ["def build(n, v):", f"    return cls(n{args})"]
        namespace: dict[str, Any] = {"cls": cls}
        exec(compile("\n".join(lines), f"<signal binding {cls.__name__}>", "exec"), namespace)  # noqa: S102
        self.values: Callable[[Any], list[Any]] = namespace["values"]
        self.build: Callable[[int, Any], Frame] = namespace["build"]


def binding_of(cls: type[Frame], names: tuple[str, ...]) -> SignalBinding | None:
    """The `SignalBinding` of a frame type with the plain `FIELDS` mapping; None when it maps its own way
    (`Heartbeat`: the flag bits) and goes through `to_signals` / `from_signals`."""
    return None if "to_signals" in cls.__dict__ or "from_signals" in cls.__dict__ else SignalBinding(cls, names)


def check_node_id(node_id: Any) -> int:
    if not isinstance(node_id, numbers.Integral) or not NODE_ID_MIN <= int(node_id) <= NODE_ID_MAX:
        raise MalformedFrame(f"node id {node_id!r} not in {NODE_ID_MIN}..{NODE_ID_MAX}")
    return int(node_id)


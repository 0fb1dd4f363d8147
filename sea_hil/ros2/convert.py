"""A session recording as ROS 2 messages (`sea-hil export --ros2`, docs/ros2.md): which topic, type, times and
fields each recorded message becomes. Pure: a `SessionData` in, `BagMessage`s out in log-time order; writing the
rosbag2 directory is `sea_hil.ros2.bag`.

Topics (a namespace `/<limb>` per limb when the session has several, none with one): `joint_states`
(sensor_msgs/JointState from the drive feedback, one per sample: hip and knee angle, velocity, effort = SEA spring
torque -k Delta a(theta) of Eq. 4), `joint_states_desired` (the desired angles of `/tracking`), `state` and
`setpoint` (sea_hil_msgs: the event-triggered Zenoh traffic), `from_can_bus` (can_msgs/Frame, one per recorded
frame, ros2_socketcan's topic and type; a CAN FD session: `from_can_bus_fd`, ros2_socketcan_msgs/FdFrame, as
ros2_socketcan publishes with `enable_can_fd`), and the global `/rosout` (rcl_interfaces/Log: trigger events and
driver faults) and `/diagnostics` (diagnostic_msgs/DiagnosticArray: driver heartbeats, or in a cia402 session the
nodes' statusword TPDOs, node statistics, the recorder's final counters).

Times: a message's log time (and publish time) is its source message's MCAP log time, i.e. the recording's clock
(wall clock in real time, the sample time in lockstep: `sea_hil.recorder.clock`); `header.stamp` (and Log.stamp) is
the session's sample time of what the message describes: the drive's clock for feedback and frames (the frame's
node's latest FEEDBACK_ANGLE, as the lockstep recorder logs frames), the state's `sample_t_ns` for states, the
sample time of the state answered (`state_seq`) for setpoints and desired motion, otherwise the newest sample time
at that log time. In a lockstep recording the two agree for feedback and frames.
"""
from __future__ import annotations

import heapq
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import MalformedFrame
from sea_hil.mechanics import LimbParams, limb_params, sea_geometry
from sea_hil.protocol.can_assembly import unwrap_us
from sea_hil.protocol.cia402_decode import decoder_for
from sea_hil.protocol.drive_state import drive_state_reader
from sea_hil.recorder.meta import META_FINAL
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.ros2.diagnostics import counter_status, hardware_id, heartbeat_status
from sea_hil.ros2.timeline import Limbs, NodeClock, StateClock, limb_of_key

JOINT_STATE = "sensor_msgs/msg/JointState"
CAN_FRAME = "can_msgs/msg/Frame"
CAN_FD_FRAME = "ros2_socketcan_msgs/msg/FdFrame"
LOG = "rcl_interfaces/msg/Log"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
LIMB_STATE = "sea_hil_msgs/msg/LimbState"
SETPOINT = "sea_hil_msgs/msg/Setpoint"
JOINT_NAMES = ["hip", "knee"]
CAN_FRAME_ID = "can"          # header.frame_id ros2_socketcan's receiver writes
# foxglove.LogLevel (the recording's /log/*) -> rcl_interfaces/Log level
LOG_LEVELS = {0: 20, 1: 10, 2: 20, 3: 30, 4: 40, 5: 50}


class BagMessage(NamedTuple):
    """One message of the bag: where, what type, when (ns, the recording's clock) and its fields (a dict the CDR
    encoder of `type_name` takes)."""
    log_time_ns: int
    topic: str
    type_name: str
    message: dict[str, Any]
    sequence: int = 0


def stamp(t_ns: int) -> dict[str, int]:
    """builtin_interfaces/Time of integer nanoseconds."""
    sec, nanosec = divmod(int(t_ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def header(t_ns: int, frame_id: str = "") -> dict[str, Any]:
    return {"stamp": stamp(t_ns), "frame_id": frame_id}


def _f(v: Any) -> float:
    """A recorded number as float64 (null, i.e. a non-finite value in the recording, -> NaN)."""
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def _u(v: Any, bits: int = 32) -> int:
    return int(v) if isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 1 << bits else 0


def _s(v: Any) -> str:
    return v if isinstance(v, str) else ""


@dataclass
class _Sample:
    """One drive sample being assembled from its feedback frames (ANGLE + JOINT1 + JOINT2, or one FD frame)."""
    seq: Any
    sample_ns: int
    values: dict[str, float] = field(default_factory=dict)


_SAMPLE_KEYS = ("theta1_rad", "theta2_rad", "omega1_rad_s", "omega2_rad_s", "delta1_m", "delta2_m")


@dataclass
class Converter:
    """Turns one recording into bag messages (`messages()`); `fd` picks the CAN FD frame type (a session that
    recorded a CAN FD frame)."""
    data: SessionData
    config: SeaHilConfig | None = None
    limbs: Limbs = field(init=False)
    fd: bool = field(init=False)

    def __post_init__(self) -> None:
        self.limbs = Limbs.of(self.data)
        raw = self.data.messages.get("/can/raw", [])
        self.fd = any(m.payload.get("is_fd") for m in raw)
        self.node_clock = NodeClock(self.data.messages.get("/can/feedback", []))
        period_ns = round(1e9 / self.config.can.feedback_rate_hz) if self.config else 1_000_000
        by_limb: dict[str | None, list[RecordedMessage]] = {}
        for m in self.data.messages.get("/zenoh/state", []):
            by_limb.setdefault(limb_of_key(m.payload.get("key")), []).append(m)
        self.state_clocks = {limb: StateClock(ms, period_ns) for limb, ms in by_limb.items()}
        self._default_state_clock = StateClock([], period_ns)
        self._params: LimbParams | None = limb_params(self.config.plant) if self.config else None
        self.end_ns = max((ms[-1].log_time_ns for ms in self.data.messages.values() if ms), default=0)

    # -- the streams ----------------------------------------------------------------------------------------------
    def messages(self) -> Iterator[BagMessage]:
        """Every bag message, in log-time order (ties: stream order below, then recording order)."""
        streams = [self.can_frames(), self.joint_states(), self.desired(), self.states(), self.setpoints(),
                   self.rosout(), self.stats_diagnostics(), self.final_diagnostics()]
        return heapq.merge(*streams, key=lambda b: b.log_time_ns)

    def can_frames(self) -> Iterator[BagMessage]:
        """One can_msgs/Frame (FdFrame in a CAN FD session) per `/can/raw` frame, plus one DiagnosticArray per
        driver HEARTBEAT (decoded through the DBC); in a cia402 session per statusword TPDO instead (EMCYs set its
        flags; no frame is read through the DBC): `protocol.drive_state`, the report's and live view's reader."""
        cfg = self.config
        reader = drive_state_reader(decoder_for(cfg) if cfg is not None and cfg.can.profile == "cia402" else None)
        for m in self.data.messages.get("/can/raw", []):
            p = m.payload
            try:
                can_id, dlc, data = int(p["can_id"]), int(p["dlc"]), bytes.fromhex(p["data_hex"])
            except (KeyError, TypeError, ValueError):
                continue   # not a frame: nothing to carry
            node = p.get("node_id")
            limb = self.limbs.of_node(node)
            t = self.node_clock.at(node, m.log_time_ns)
            ext = bool(p.get("is_extended", False))
            if self.fd:
                msg: dict[str, Any] = {"header": header(t, CAN_FRAME_ID), "id": can_id, "is_extended": ext,
                                       "is_error": False, "len": len(data), "data": data}
                yield BagMessage(m.log_time_ns, f"{self.limbs.ns(limb)}/from_can_bus_fd", CAN_FD_FRAME, msg,
                                 m.sequence)
            else:
                msg = {"header": header(t, CAN_FRAME_ID), "id": can_id, "is_rtr": False, "is_extended": ext,
                       "is_error": False, "dlc": dlc, "data": data[:8].ljust(8, b"\0")}
                yield BagMessage(m.log_time_ns, f"{self.limbs.ns(limb)}/from_can_bus", CAN_FRAME, msg, m.sequence)
            try:
                d = reader.on_frame(can_id, data, dlc, extended=ext, fd=bool(p.get("is_fd", False)))
            except MalformedFrame:
                continue   # a malformed heartbeat: its frame above, no status
            if d is None:
                continue
            yield BagMessage(m.log_time_ns, "/diagnostics", DIAGNOSTICS,
                             {"header": header(t), "status": [heartbeat_status(d, self._name(limb, f"driver{d.node_id}"))]}, m.sequence)

    def _name(self, limb: str | None, what: str) -> str:
        return f"{limb}/{what}" if limb and len(self.limbs.names) > 1 else what

    def joint_states(self) -> Iterator[BagMessage]:
        """One JointState per drive sample (a re-sent sample, same drive time, once), from `/can/feedback`, logged
        when its last frame was; effort = the SEA spring torques (empty without the recording's config)."""
        current: dict[Any, _Sample] = {}
        last_done: dict[Any, int] = {}
        full_us: dict[Any, int] = {}
        for m in self.data.messages.get("/can/feedback", []):
            p = m.payload
            node, t_us = p.get("node_id"), p.get("t_us")
            if isinstance(t_us, int):
                try:
                    full_us[node] = t_us if node not in full_us else unwrap_us(full_us[node], t_us)
                except MalformedFrame:
                    continue
                current[node] = _Sample(p.get("seq"), full_us[node] * 1000)
            s = current.get(node)
            if s is None or p.get("seq") != s.seq:
                continue
            s.values.update({k: _f(p[k]) for k in _SAMPLE_KEYS if k in p})
            if len(s.values) < len(_SAMPLE_KEYS) or last_done.get(node) == s.sample_ns:
                continue
            last_done[node] = s.sample_ns
            v = s.values
            msg = {"header": header(s.sample_ns), "name": JOINT_NAMES,
                   "position": [v["theta1_rad"], v["theta2_rad"]], "velocity": [v["omega1_rad_s"], v["omega2_rad_s"]],
                   "effort": self._spring_torque(v)}
            yield BagMessage(m.log_time_ns, f"{self.limbs.ns(self.limbs.of_node(node))}/joint_states", JOINT_STATE,
                             msg, m.sequence)

    def _spring_torque(self, v: Mapping[str, float]) -> list[float]:
        """Eq. 4: tau_i = -k_i Delta_i a_i(theta), a_i the SEA moment arm at the sample's angles."""
        p = self._params
        if p is None or not all(math.isfinite(v[k]) for k in ("theta1_rad", "theta2_rad")):
            return [] if p is None else [math.nan, math.nan]
        _, _, a1, a2, _, _ = sea_geometry(v["theta1_rad"], v["theta2_rad"], p)
        return [-p.k1 * v["delta1_m"] * a1, -p.k2 * v["delta2_m"] * a2]

    def _state_time(self, limb: str | None, state_seq: Any, log_time_ns: int) -> int:
        t = self.state_clocks.get(limb, self._default_state_clock).at(state_seq)
        return self.node_clock.newest(log_time_ns) if t is None else t

    def desired(self) -> Iterator[BagMessage]:
        """The desired angles (`/tracking`) as JointState positions (velocity and effort empty)."""
        for m in self.data.messages.get("/tracking", []):
            p = m.payload
            limb = limb_of_key(p.get("key"))
            msg = {"header": header(self._state_time(limb, p.get("state_seq"), m.log_time_ns)), "name": JOINT_NAMES,
                   "position": [_f(p.get("theta1_d_rad")), _f(p.get("theta2_d_rad"))], "velocity": [], "effort": []}
            yield BagMessage(m.log_time_ns, f"{self.limbs.ns(limb)}/joint_states_desired", JOINT_STATE, msg,
                             m.sequence)

    def states(self) -> Iterator[BagMessage]:
        for m in self.data.messages.get("/zenoh/state", []):
            p = m.payload
            limb = limb_of_key(p.get("key"))
            t = p["sample_t_ns"] if isinstance(p.get("sample_t_ns"), int) else self.node_clock.newest(m.log_time_ns)
            msg = {"header": header(t), "seq": _u(p.get("seq")), "payload_bytes": _u(p.get("payload_bytes")),
                   "sent_t_ns": _u(p.get("sent_t_ns"), 64),
                   **{k: _f(p.get(k)) for k in ("theta1_rad", "theta2_rad", "omega1_rad_s", "omega2_rad_s",
                                                  "delta1_m", "delta2_m", "nut_vel1_m_s", "nut_vel2_m_s")},
                   "event_seq": _u(p.get("event_seq")), "reason": _s(p.get("reason")),
                   "trajectory_id": _u(p.get("trajectory_id"))}
            yield BagMessage(m.log_time_ns, f"{self.limbs.ns(limb)}/state", LIMB_STATE, msg, m.sequence)

    def setpoints(self) -> Iterator[BagMessage]:
        for m in self.data.messages.get("/zenoh/setpoint", []):
            p = m.payload
            limb = limb_of_key(p.get("key"))
            msg = {"header": header(self._state_time(limb, p.get("state_seq"), m.log_time_ns)),
                   "seq": _u(p.get("seq")), "state_seq": _u(p.get("state_seq")),
                   "payload_bytes": _u(p.get("payload_bytes")), "sent_t_ns": _u(p.get("sent_t_ns"), 64),
                   **{k: _f(p.get(k)) for k in ("delta1_ref_m", "delta2_ref_m", "s1", "s2")},
                   "reason": _s(p.get("reason"))}
            yield BagMessage(m.log_time_ns, f"{self.limbs.ns(limb)}/setpoint", SETPOINT, msg, m.sequence)

    def rosout(self) -> Iterator[BagMessage]:
        """`/log/events` and `/log/faults` as rcl_interfaces/Log on `/rosout`. An event's limb is the one of the
        `/tracking` event it was made from (the recorder writes the two together, in the same order)."""
        events = self.data.messages.get("/log/events", [])
        sources = [m for m in self.data.messages.get("/tracking", []) if m.payload.get("event") is True]
        paired = len(sources) == len(events) and all(
            (a.log_time_ns, a.sequence) == (b.log_time_ns, b.sequence) for a, b in zip(sources, events, strict=True))
        ev = [(m, sources[i] if paired else None) for i, m in enumerate(events)]
        faults = [(m, None) for m in self.data.messages.get("/log/faults", [])]
        for m, src in heapq.merge(ev, faults, key=lambda x: x[0].log_time_ns):
            p = m.payload
            name = _s(p.get("name"))
            if src is not None:
                limb = limb_of_key(src.payload.get("key"))
                t = self._state_time(limb, src.payload.get("state_seq"), m.log_time_ns)
                name = self._name(limb, name)
            elif name.startswith("driver") and name[6:].isdigit():
                t = self.node_clock.at(int(name[6:]), m.log_time_ns)
            else:
                t = self.node_clock.newest(m.log_time_ns)
            level = p.get("level")
            msg = {"stamp": stamp(t), "level": LOG_LEVELS.get(level if isinstance(level, int) else 0, 20),
                   "name": name, "msg": _s(p.get("message")), "file": _s(p.get("file")), "function": "",
                   "line": _u(p.get("line"))}
            yield BagMessage(m.log_time_ns, "/rosout", LOG, msg, m.sequence)

    def stats_diagnostics(self) -> Iterator[BagMessage]:
        """One DiagnosticArray per `/stats` record (edge: link counters and latency; controller; ...)."""
        for m in self.data.messages.get("/stats", []):
            p = m.payload
            node = _s(p.get("node")) or "node"
            limb = self.limbs.of_node(p.get("node_id"))
            values = {k: v for k, v in p.items() if k not in ("node",)}
            yield BagMessage(m.log_time_ns, "/diagnostics", DIAGNOSTICS,
                             {"header": header(self.node_clock.newest(m.log_time_ns)),
                              "status": [counter_status(self._name(limb, node), values,
                                                              hardware_id(p.get("node_id")))]},
                             m.sequence)

    def final_diagnostics(self) -> Iterator[BagMessage]:
        """The recorder's final counters (metadata `sea-hil.final`) as one DiagnosticArray at the last log time."""
        final = self.data.metadata.get(META_FINAL)
        if final:
            yield BagMessage(self.end_ns, "/diagnostics", DIAGNOSTICS,
                             {"header": header(self.node_clock.newest(self.end_ns)),
                              "status": [counter_status("recorder", final, "")]})

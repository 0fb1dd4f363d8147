"""What one Zenoh message becomes in a recording (the Zenoh counterpart of `sea_hil.recorder.can_tap`). Pure.

`zenoh_record` flattens one message into its sea-hil channel; `ZenohTap` adds the log time (`time_base`, see
`sea_hil.recorder.clock`), the MCAP `sequence` (the sender's sequence number: `seq` of binary payloads, `state_seq`
of trigger events, 0 for stats) and the Foxglove well-known messages: `/joint_states` for every state, `/log/events` for
every trigger event. `publish_time` equals `log_time`: the senders stamp their payloads with their own
`time.monotonic_ns()` (kept in the payload as `sent_t_ns`), a clock the recorder cannot place on its time axis.
"""
from __future__ import annotations

import json
import logging
from typing import Any

from sea_hil.protocol.keys import KEY_PAYLOADS
from sea_hil.protocol.payloads import (
    AckPayload,
    EventStatePayload,
    PayloadCounters,
    SetpointPayload,
    StatePayload,
    VoltagePayload,
)
from sea_hil.recorder.can_tap import Record
from sea_hil.recorder.clock import SampleClock, TimeBase, check_time_base
from sea_hil.recorder.well_known import LogLevel, joint_states, log_message
from sea_hil.stats.schema import StatsError, validate_stats

log = logging.getLogger("sea_hil.record")


def zenoh_record(key: str, data: bytes, payloads: PayloadCounters) -> tuple[str, dict[str, Any]] | None:
    """(topic, flat payload) for one Zenoh message, or None if it is not recordable."""
    channel = key.rsplit("/", 1)[-1]
    if channel in ("event", "stats"):
        try:
            obj = json.loads(data)
        except (ValueError, UnicodeDecodeError):
            payloads.rejected["json"] += 1
            return None
        if not isinstance(obj, dict):
            return None
        if channel == "stats":   # one schema for every node's stats (`StatsError` if a record breaks it)
            validate_stats(obj)
            return "/stats", obj
        flat = {k: v for k, v in obj.items() if isinstance(v, (int, float, str, bool)) or v is None}
        flat["key"] = key
        return "/tracking", flat
    p = payloads.try_decode(data, KEY_PAYLOADS.get(channel))   # a type its key does not carry: counted, not recorded
    if p is None:
        return None
    base: dict[str, Any] = {"key": key, "seq": p.seq, "sent_t_ns": p.t_ns, "payload_bytes": len(data)}
    if isinstance(p, StatePayload):
        state = {**base, "sample_t_ns": p.sample_t_ns, "theta1_rad": p.theta_rad[0], "theta2_rad": p.theta_rad[1],
                 "omega1_rad_s": p.omega_rad_s[0], "omega2_rad_s": p.omega_rad_s[1], "delta1_m": p.delta_m[0],
                 "delta2_m": p.delta_m[1], "nut_vel1_m_s": p.nut_vel_m_s[0], "nut_vel2_m_s": p.nut_vel_m_s[1]}
        if isinstance(p, EventStatePayload):   # the edge trigger's state: `seq` is the sample's, `event_seq` counts
            state.update(event_seq=p.event_seq, reason=p.reason.name, trajectory_id=p.trajectory_id)   # the events
        return "/zenoh/state", state
    if isinstance(p, SetpointPayload):
        return "/zenoh/setpoint", {**base, "state_seq": p.state_seq, "delta1_ref_m": p.deflection_m[0],
                                   "delta2_ref_m": p.deflection_m[1], "s1": p.sliding[0], "s2": p.sliding[1],
                                   "reason": p.reason.name}
    if isinstance(p, VoltagePayload):
        return "/zenoh/voltage", {**base, "state_seq": p.state_seq, "u1_v": p.voltage_v[0], "u2_v": p.voltage_v[1]}
    if isinstance(p, AckPayload):
        return None   # lockstep control plane
    return None


class ZenohTap:
    """`zenoh_record` plus log time, sequence and the well-known messages of one Zenoh message; `take` also keeps
    the recorder's Zenoh counters (`counters`)."""

    def __init__(self, payloads: PayloadCounters | None = None, time_base: TimeBase = "wall") -> None:
        self.payloads = payloads or PayloadCounters()
        self.time_base = check_time_base(time_base)
        self.clock = SampleClock()
        self.msgs = 0             # messages recorded
        self.stats_rejected = 0   # stats records from the wire that break the stats schema

    def take(self, key: str, data: bytes, rx_wall_ns: int) -> list[Record]:
        """`records`, counted; a stats record that breaks the stats schema is bad input from the wire: counted,
        logged, not recorded."""
        try:
            recs = self.records(key, data, rx_wall_ns)
        except StatsError as err:
            self.stats_rejected += 1
            log.warning("stats message not recorded: %s", err)
            return []
        self.msgs += bool(recs)
        return recs

    def counters(self) -> dict[str, Any]:
        return {"zenoh_msgs": self.msgs, "stats_rejected": self.stats_rejected,
                **{f"payload_{k}": v for k, v in self.payloads.as_dict().items() if not isinstance(v, dict)}}

    def records(self, key: str, data: bytes, rx_wall_ns: int) -> list[Record]:
        """The messages of one Zenoh message received at wall time `rx_wall_ns` (empty if not recordable)."""
        out = zenoh_record(key, data, self.payloads)
        if out is None:
            return []
        topic, p = out
        if topic == "/zenoh/state":
            sample_ns = self.clock.on_state(p["seq"], p["sample_t_ns"])
        elif "state_seq" in p and isinstance(p["state_seq"], int):
            sample_ns = self.clock.state_ns(p["state_seq"])
        else:
            sample_ns = self.clock.now_ns
        t = rx_wall_ns if self.time_base == "wall" else sample_ns
        seq = p.get("seq", p.get("state_seq", 0))
        seq = seq if isinstance(seq, int) and 0 <= seq < 1 << 32 else 0
        recs = [Record(topic, t, t, p, seq)]
        if topic == "/zenoh/state":
            recs.append(Record("/joint_states", t, t, joint_states(
                t, (p["theta1_rad"], p["theta2_rad"]), (p["omega1_rad_s"], p["omega2_rad_s"]),
                (p["delta1_m"], p["delta2_m"])), seq))
        elif topic == "/tracking" and p.get("event") is True:
            t_s = p.get("t_s")
            at = f"{t_s:.3f} s" if isinstance(t_s, (int, float)) else "?"
            text = (f"trigger event {p.get('reason') or '?'} at t = {at} (state {p.get('state_seq')}, "
                    f"setpoint {p.get('setpoint_seq')})")
            recs.append(Record("/log/events", t, t, log_message(t, LogLevel.INFO, "controller", text), seq))
        return recs

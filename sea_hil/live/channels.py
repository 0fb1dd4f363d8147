"""The live view's channels: topic -> (schema name, JSON schema). Pure data, no SDK import.

Every channel is JSON-encoded with a JSON schema (Foxglove's `jsonschema` encoding), so any Foxglove WebSocket client
can decode it. `/live/events` uses Foxglove's well-known `foxglove.Log` schema (its JSON form), so the Log panel
shows trigger events, driver state changes and faults with no set-up. The fields and their clocks are documented in
docs/foxglove/README.md.
"""
from __future__ import annotations

from typing import Any

_NUM = {"type": ["number", "null"]}
_INT = {"type": "integer"}
_STR = {"type": "string"}
_BOOL = {"type": "boolean"}

END_MESSAGE = "session ended"   # the last /live/events message of a session (name "sea-hil")

# foxglove.Log in JSON form (https://docs.foxglove.dev/docs/visualization/message-schemas/log)
LOG_LEVELS = {"UNKNOWN": 0, "DEBUG": 1, "INFO": 2, "WARNING": 3, "ERROR": 4, "FATAL": 5}
FOXGLOVE_LOG_SCHEMA: dict[str, Any] = {
    "title": "foxglove.Log", "description": "A log message", "type": "object",
    "properties": {
        "timestamp": {"type": "object", "title": "time", "description": "Timestamp of log message",
                      "properties": {"sec": {"type": "integer", "minimum": 0},
                                     "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
        "level": {"title": "foxglove.LogLevel", "description": "Log level",
                  "oneOf": [{"title": k, "const": v} for k, v in LOG_LEVELS.items()]},
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
}


def _obj(title: str, description: str, props: dict[str, Any]) -> dict[str, Any]:
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title, "description": description,
            "type": "object", "properties": props, "required": list(props), "additionalProperties": False}


_JOINTS = {"theta1_rad": _NUM, "theta2_rad": _NUM, "theta1_d_rad": _NUM, "theta2_d_rad": _NUM,
           "e1_rad": _NUM, "e2_rad": _NUM}
_RATES = {f"{d}_{q}": _NUM for d in ("up", "down") for q in ("msgs_per_s", "bytes_per_s")}
_TOTALS = {f"{d}_{q}": _INT for d in ("up", "down") for q in ("msgs", "bytes")}
_LATENCY = {f"rtt_{q}_us": _NUM for q in ("last", "p50", "p90", "p99", "max")}
_FLAGS = {f"err_{f}": _BOOL for f in ("watchdog", "estop", "bad_frame", "overrun", "bus_error", "saturated")}

CHANNELS: dict[str, tuple[str, dict[str, Any]]] = {
    "/live/tracking": ("sea_hil.live.Tracking", _obj(
        "sea_hil.live.Tracking", "Desired and measured joint angles and tracking errors e = theta_d - theta, one "
        "per controller sample (the recording's /tracking).",
        {"t_s": _NUM, "state_seq": _INT, **_JOINTS, "event": _BOOL, "reason": _STR})),
    "/live/setpoint": ("sea_hil.live.Setpoint", _obj(
        "sea_hil.live.Setpoint", "Setpoint v_x(t_i) sent on an event, with its trigger reason (the recording's "
        "/zenoh/setpoint).",
        {"seq": _INT, "state_seq": _INT, "delta1_ref_m": _NUM, "delta2_ref_m": _NUM, "s1": _NUM, "s2": _NUM,
         "reason": _STR, "reason_code": _INT})),
    "/live/events": ("foxglove.Log", FOXGLOVE_LOG_SCHEMA),
    "/live/link": ("sea_hil.live.Link", _obj(
        "sea_hil.live.Link", "Zenoh link statistics seen by the recorder: up = state (edge -> controller), down = "
        "setpoints and voltages (controller -> edge); rates over the last window_s; rtt = state k received -> its "
        "setpoint received, on the recorder's clock (session percentiles).",
        {**_RATES, **_TOTALS, **_LATENCY, "rtt_count": _INT, "window_s": _NUM})),
    "/live/bus": ("sea_hil.live.Bus", _obj(
        "sea_hil.live.Bus", "CAN bus load from the frames seen (worst-case stuffing, sea_hil.stats.can_frame_bits).",
        {"frames": _INT, "frames_per_s": _NUM, "load_pct": _NUM, "load_pct_session": _NUM, "bitrate_bps": _INT,
         "window_s": _NUM})),
    "/live/driver": ("sea_hil.live.Driver", _obj(
        "sea_hil.live.Driver", "Driver state from each HEARTBEAT frame.",
        {"node_id": _INT, "state": _INT, "state_name": _STR, **_FLAGS, "rejected_frames": _INT, "overruns": _INT,
         "seq": _INT})),
    "/live/verdict": ("sea_hil.live.Verdict", _obj(
        "sea_hil.live.Verdict", "The session's running verdict: summary.json's rules on what the live view has seen "
        "(drive latches, the nodes' latest /stats counters; not the recording's completeness or tick misses); final: "
        "the last message, at the end of the stream.",
        {"status": {"enum": ["ok", "degraded", "invalid"]}, "codes": {"type": "array", "items": _STR},
         "reasons": {"type": "array", "items": _STR}, "final": _BOOL})),
    "/live/node_stats": ("sea_hil.live.NodeStats", {
        "$schema": "https://json-schema.org/draft/2020-12/schema", "title": "sea_hil.live.NodeStats",
        "description": "A node's own statistics as published on its Zenoh stats key (the recording's /stats).",
        "type": "object", "additionalProperties": {"type": ["number", "boolean", "null"]}}),
}
TOPICS: tuple[str, ...] = tuple(CHANNELS)

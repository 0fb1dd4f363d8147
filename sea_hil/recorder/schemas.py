"""JSON schemas (draft 2020-12, MCAP schema encoding "jsonschema") of the recorder's channels.

Every sea-hil channel message is one flat JSON object of scalars so Foxglove can plot each numeric field. Listed
properties document the expected fields; further flat scalar fields are allowed (`additionalProperties` is a
scalar). The high-rate CAN channels (`/can/raw`, `/can/feedback`, `/can/command`) are recorded in protobuf
(`sea_hil.recorder.binary`: the same fields, decoded back into the same flat dicts); their JSON schema here documents
the decoded payload. The Foxglove well-known channels (`/log/*`, `/joint_states`) keep Foxglove's own nested schemas
(`sea_hil.recorder.well_known`). `validate_payload` is the cheap check the recorder applies (required keys present,
every value a scalar; the well-known channels: their structure); `/stats` follows the one stats schema of every
node (`sea_hil.stats.schema`: `node`, `final`, `t_ns`, then numbers only).
"""
from __future__ import annotations

import json
import numbers
from collections.abc import Mapping
from typing import Any

from sea_hil.errors import RecordingError
from sea_hil.recorder import binary
from sea_hil.recorder.meta import encode_payload
from sea_hil.recorder.well_known import WELL_KNOWN, validate_well_known
from sea_hil.stats.schema import ENVELOPE, STATS_JSON_SCHEMA, STATS_PROPERTIES, StatsError, validate_stats

SCALAR_TYPES = ["number", "integer", "boolean", "string", "null"]
_NUM = {"type": ["number", "null"]}  # null: a non-finite float is written as null
_INT = {"type": "integer"}
_STR = {"type": "string"}

_JOINT_STATE = {"theta1_rad": _NUM, "theta2_rad": _NUM, "omega1_rad_s": _NUM, "omega2_rad_s": _NUM,
                "delta1_m": _NUM, "delta2_m": _NUM, "nut_vel1_m_s": _NUM, "nut_vel2_m_s": _NUM}
_VOLTS = {"u1_v": _NUM, "u2_v": _NUM}
_DEFLECTION_REF = {"delta1_ref_m": _NUM, "delta2_ref_m": _NUM}

# topic -> (schema title, description, properties, required)
_CHANNELS: dict[str, tuple[str, str, dict[str, Any], list[str]]] = {
    "/can/raw": ("sea_hil.CanFrame", "Every CAN frame seen on the bus.",
                 {"t_ns": _INT, "can_id": _INT, "is_extended": {"type": "boolean"}, "is_fd": {"type": "boolean"}, "dlc": _INT,
                  "data_hex": _STR, "direction": {"enum": ["rx", "tx"]}, "node_id": _INT},
                 ["can_id", "dlc", "data_hex", "direction"]),
    "/can/feedback": ("sea_hil.CanFeedback", "Decoded driver feedback, one message per node and frame set.",
                      {"t_ns": _INT, "node_id": _INT, "seq": _INT, "t_us": _INT, **_JOINT_STATE, "r1_m": _NUM,
                       "r2_m": _NUM, "status": _INT}, ["node_id"]),
    "/can/command": ("sea_hil.CanCommand", "Decoded voltage / deflection commands sent to a node.",
                     {"t_ns": _INT, "node_id": _INT, "seq": _INT, "kind": _STR, **_VOLTS, **_DEFLECTION_REF},
                     ["node_id"]),
    "/zenoh/state": ("sea_hil.ZenohState", "Joint state published by the edge node over Zenoh (with the trigger at "
                     "the edge: its event number, reason and trajectory identity too).",
                     {"t_ns": _INT, "seq": _INT, "sent_t_ns": _INT, "sample_t_ns": _INT, **_JOINT_STATE,
                      "latency_s": _NUM, "event_seq": _INT, "reason": _STR, "trajectory_id": _INT}, []),
    "/zenoh/setpoint": ("sea_hil.ZenohSetpoint", "Event-triggered setpoint from the remote controller.",
                        {"t_ns": _INT, "seq": _INT, "event_index": _INT, **_DEFLECTION_REF,
                         "tau1_nm": _NUM, "tau2_nm": _NUM, "theta1_d_rad": _NUM, "theta2_d_rad": _NUM,
                         "latency_s": _NUM}, []),
    "/zenoh/voltage": ("sea_hil.ZenohVoltage", "Motor voltages computed by the edge inner loop.",
                       {"t_ns": _INT, "seq": _INT, **_VOLTS}, []),
    "/controller/event": ("sea_hil.TriggerEvent", "One trigger event of the event-triggered SMC.",
                          {"t_ns": _INT, "event_index": _INT, "reason": _STR, "inter_event_s": _NUM,
                           "error_norm": _NUM, "threshold": _NUM}, ["reason"]),
    "/stats": ("sea_hil.Stats", STATS_JSON_SCHEMA["description"], STATS_PROPERTIES, list(ENVELOPE)),
    "/tracking": ("sea_hil.Tracking", "Desired vs actual joint angles and tracking errors.",
                  {"t_ns": _INT, "theta1_d_rad": _NUM, "theta2_d_rad": _NUM, "theta1_rad": _NUM,
                   "theta2_rad": _NUM, "e1_rad": _NUM, "e2_rad": _NUM}, []),
}

TOPICS: tuple[str, ...] = (*_CHANNELS, *WELL_KNOWN)


def schema_for(topic: str) -> dict[str, Any]:
    """The JSON schema (as a dict) of `topic`; `RecordingError` for an unknown topic."""
    if topic in WELL_KNOWN:
        return {"$schema": "https://json-schema.org/draft/2020-12/schema", **WELL_KNOWN[topic][1]}
    try:
        title, desc, props, required = _CHANNELS[topic]
    except KeyError as err:
        raise RecordingError(f"unknown recording topic {topic!r}; known: {', '.join(TOPICS)}") from err
    if topic == "/stats":
        return dict(STATS_JSON_SCHEMA)
    extra = {"type": SCALAR_TYPES}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title, "description": desc,
            "type": "object", "properties": props, "required": required, "additionalProperties": extra}


def schema_name(topic: str) -> str:
    if topic in binary.BINARY_TOPICS:
        return binary.schema_name(topic)
    return WELL_KNOWN[topic][0] if topic in WELL_KNOWN else _CHANNELS[topic][0]


def schema_bytes(topic: str) -> bytes:
    """The data of `topic`'s MCAP schema record: its JSON schema, or a binary channel's FileDescriptorSet."""
    if topic in binary.BINARY_TOPICS:
        return binary.schema_data()
    return json.dumps(schema_for(topic), sort_keys=True).encode()


def encodings(topic: str) -> tuple[str, str]:
    """(MCAP schema encoding, message encoding) of `topic`."""
    if topic in binary.BINARY_TOPICS:
        return binary.SCHEMA_ENCODING, binary.MESSAGE_ENCODING
    return "jsonschema", "json"


def message_bytes(topic: str, payload: Mapping[str, Any]) -> bytes:
    """One message of `topic`, checked and encoded: `validate_payload` + compact JSON, or for a binary channel the
    required fields + protobuf (whose encoder refuses unknown fields and wrong types); `RecordingError` if bad."""
    if topic in binary.BINARY_TOPICS:
        if type(payload) is not dict and not isinstance(payload, Mapping):   # (the ABC check costs ~0.3 us)
            raise RecordingError(f"{topic}: payload must be a mapping, got {type(payload).__name__}")
        missing = [k for k in _CHANNELS[topic][3] if k not in payload]
        if missing:
            raise RecordingError(f"{topic}: missing required field(s) {missing}")
        return binary.encode(topic, payload)
    validate_payload(topic, payload)
    return encode_payload(payload)


def encoded_payload(topic: str, payload: Mapping[str, Any]) -> bytes:
    """`message_bytes` of a payload `validate_payload` has already passed (the recorder process encodes what its
    parent checked): the encoding alone."""
    return binary.encode(topic, payload) if topic in binary.BINARY_TOPICS else encode_payload(payload)


def message_payload(topic: str, data: bytes) -> dict[str, Any]:
    """The payload dict of one encoded message of `topic` (`message_bytes` read back, as the reader decodes it);
    `RecordingError` if `data` is not one."""
    if topic in binary.BINARY_TOPICS:
        return binary.decode(topic, data)
    try:
        payload = json.loads(data)
    except ValueError as err:
        raise RecordingError(f"{topic}: undecodable JSON message: {err}") from err
    if not isinstance(payload, dict):
        raise RecordingError(f"{topic}: a message must be a JSON object, got {type(payload).__name__}")
    return payload


def validate_payload(topic: str, payload: Mapping[str, Any]) -> None:
    """Cheap structural check: known topic, a mapping of str keys to scalars, required keys present."""
    if topic not in _CHANNELS and topic not in WELL_KNOWN:
        schema_for(topic)  # raises with the list of topics
    if not isinstance(payload, Mapping):
        raise RecordingError(f"{topic}: payload must be a mapping, got {type(payload).__name__}")
    if topic in WELL_KNOWN:
        validate_well_known(topic, payload)
        return
    if topic == "/stats":
        try:
            validate_stats(payload)
        except StatsError as err:
            raise RecordingError(f"/stats: {err}") from err
        return
    missing = [k for k in _CHANNELS[topic][3] if k not in payload]
    if missing:
        raise RecordingError(f"{topic}: missing required field(s) {missing}")
    for k, v in payload.items():
        if not isinstance(k, str):
            raise RecordingError(f"{topic}: field names must be strings, got {k!r}")
        ok = v is None or isinstance(v, (numbers.Real, str))
        if not ok:
            raise RecordingError(f"{topic}.{k}: value must be a flat scalar, got {type(v).__name__}")

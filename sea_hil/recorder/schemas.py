"""JSON schemas (draft 2020-12, MCAP schema encoding "jsonschema") of the recorder's channels.

Every message is one flat JSON object of scalars so Foxglove can plot each numeric field. Listed properties
document the expected fields; further flat scalar fields are allowed (`additionalProperties` is a scalar).
`validate_payload` is the cheap check the recorder applies (required keys present, every value a scalar).
"""
from __future__ import annotations

import json
import numbers
from collections.abc import Mapping
from typing import Any

from sea_hil.errors import RecordingError

SCALAR_TYPES = ["number", "integer", "boolean", "string", "null"]
_NUM = {"type": ["number", "null"]}  # null: a non-finite float is written as null
_INT = {"type": "integer"}
_STR = {"type": "string"}

_JOINT_STATE = {"theta1_rad": _NUM, "theta2_rad": _NUM, "omega1_rad_s": _NUM, "omega2_rad_s": _NUM,
                "delta1_m": _NUM, "delta2_m": _NUM}
_VOLTS = {"u1_v": _NUM, "u2_v": _NUM}
_DEFLECTION_REF = {"delta1_ref_m": _NUM, "delta2_ref_m": _NUM}

# topic -> (schema title, description, properties, required)
_CHANNELS: dict[str, tuple[str, str, dict[str, Any], list[str]]] = {
    "/can/raw": ("sea_hil.CanFrame", "Every CAN frame seen on the bus.",
                 {"t_ns": _INT, "can_id": _INT, "is_extended": {"type": "boolean"}, "dlc": _INT,
                  "data_hex": _STR, "direction": {"enum": ["rx", "tx"]}, "node_id": _INT},
                 ["can_id", "dlc", "data_hex", "direction"]),
    "/can/feedback": ("sea_hil.CanFeedback", "Decoded driver feedback, one message per node and frame set.",
                      {"t_ns": _INT, "node_id": _INT, "seq": _INT, **_JOINT_STATE, "r1_m": _NUM, "r2_m": _NUM,
                       "status": _INT}, ["node_id"]),
    "/can/command": ("sea_hil.CanCommand", "Decoded voltage / deflection commands sent to a node.",
                     {"t_ns": _INT, "node_id": _INT, "seq": _INT, "kind": _STR, **_VOLTS, **_DEFLECTION_REF},
                     ["node_id"]),
    "/zenoh/state": ("sea_hil.ZenohState", "Joint state published by the edge node over Zenoh.",
                     {"t_ns": _INT, "seq": _INT, **_JOINT_STATE, "latency_s": _NUM}, []),
    "/zenoh/setpoint": ("sea_hil.ZenohSetpoint", "Event-triggered setpoint from the remote controller.",
                        {"t_ns": _INT, "seq": _INT, "event_index": _INT, **_DEFLECTION_REF,
                         "tau1_nm": _NUM, "tau2_nm": _NUM, "theta1_d_rad": _NUM, "theta2_d_rad": _NUM,
                         "latency_s": _NUM}, []),
    "/zenoh/voltage": ("sea_hil.ZenohVoltage", "Motor voltages computed by the edge inner loop.",
                       {"t_ns": _INT, "seq": _INT, **_VOLTS}, []),
    "/controller/event": ("sea_hil.TriggerEvent", "One trigger event of the event-triggered SMC.",
                          {"t_ns": _INT, "event_index": _INT, "reason": _STR, "inter_event_s": _NUM,
                           "error_norm": _NUM, "threshold": _NUM}, ["reason"]),
    "/stats": ("sea_hil.Stats", "Periodic flat statistics (SessionStats.to_flat_dict); all values numeric.",
               {"t_ns": _INT}, []),
    "/tracking": ("sea_hil.Tracking", "Desired vs actual joint angles and tracking errors.",
                  {"t_ns": _INT, "theta1_d_rad": _NUM, "theta2_d_rad": _NUM, "theta1_rad": _NUM,
                   "theta2_rad": _NUM, "e1_rad": _NUM, "e2_rad": _NUM}, []),
}
_NUMERIC_ONLY = {"/stats"}

TOPICS: tuple[str, ...] = tuple(_CHANNELS)


def schema_for(topic: str) -> dict[str, Any]:
    """The JSON schema (as a dict) of `topic`; `RecordingError` for an unknown topic."""
    try:
        title, desc, props, required = _CHANNELS[topic]
    except KeyError as err:
        raise RecordingError(f"unknown recording topic {topic!r}; known: {', '.join(TOPICS)}") from err
    extra = {"type": ["number", "null"]} if topic in _NUMERIC_ONLY else {"type": SCALAR_TYPES}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title, "description": desc,
            "type": "object", "properties": props, "required": required, "additionalProperties": extra}


def schema_name(topic: str) -> str:
    return _CHANNELS[topic][0]


def schema_bytes(topic: str) -> bytes:
    return json.dumps(schema_for(topic), sort_keys=True).encode()


def validate_payload(topic: str, payload: Mapping[str, Any]) -> None:
    """Cheap structural check: known topic, a mapping of str keys to scalars, required keys present."""
    if topic not in _CHANNELS:
        schema_for(topic)  # raises with the list of topics
    if not isinstance(payload, Mapping):
        raise RecordingError(f"{topic}: payload must be a mapping, got {type(payload).__name__}")
    missing = [k for k in _CHANNELS[topic][3] if k not in payload]
    if missing:
        raise RecordingError(f"{topic}: missing required field(s) {missing}")
    numeric_only = topic in _NUMERIC_ONLY
    for k, v in payload.items():
        if not isinstance(k, str):
            raise RecordingError(f"{topic}: field names must be strings, got {k!r}")
        if numeric_only:
            ok = v is None or isinstance(v, numbers.Real)
        else:
            ok = v is None or isinstance(v, (numbers.Real, str))
        if not ok:
            raise RecordingError(f"{topic}.{k}: value must be a flat scalar, got {type(v).__name__}")

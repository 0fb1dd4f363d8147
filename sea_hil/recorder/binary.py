"""The protobuf encoding of the recorder's high-rate channels (`/can/raw`, `/can/feedback`, `/can/command`).

One CAN frame used to cost ~9 us of JSON encoding and validation per message; a protobuf message built by the
`protobuf` package (upb) costs ~0.9 us (docs/recording.md, "Encoding"). Protobuf rather than ROS 2 CDR: proto3
`optional` fields keep presence, so a `/can/feedback` message of one FEEDBACK_JOINT1 frame still holds exactly that
frame's fields (CDR structs have no absent fields), and Foxglove reads it from the schema record alone (a
FileDescriptorSet, schema encoding `protobuf`). Every field is the channel's JSON-schema property of the same name,
numbered in the order the taps write them, so a decoded message is the dict the JSON channel held, keys in the same
order: integers `int64`, numbers `double`, strings `string`, booleans `bool`. A number that JSON wrote as null
(None, NaN, +-inf) is stored as it is (None as NaN) and decoded as None, as the JSON reader returned it.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError, Message

from sea_hil.errors import RecordingError

PROTO_FILE = "sea_hil/recording.proto"
_F = descriptor_pb2.FieldDescriptorProto
_I, _D, _S, _B = "int", "double", "string", "bool"
_TYPES = {_I: _F.TYPE_INT64, _D: _F.TYPE_DOUBLE, _S: _F.TYPE_STRING, _B: _F.TYPE_BOOL}
_JOINTS = [(f"{k}{j}_{u}", _D) for k, u in (("theta", "rad"), ("omega", "rad_s"), ("delta", "m"),
                                            ("nut_vel", "m_s")) for j in (1, 2)]

# topic -> (message name, fields in field-number order: the order the CAN tap writes them, `t_ns` last)
CHANNELS: dict[str, tuple[str, list[tuple[str, str]]]] = {
    "/can/raw": ("CanFrame", [("can_id", _I), ("dlc", _I), ("data_hex", _S), ("direction", _S),
                              ("is_extended", _B), ("node_id", _I), ("is_fd", _B), ("t_ns", _I)]),
    "/can/feedback": ("CanFeedback", [("node_id", _I), ("seq", _I), ("t_us", _I), *_JOINTS, ("r1_m", _D),
                                      ("r2_m", _D), ("status", _I), ("t_ns", _I)]),
    "/can/command": ("CanCommand", [("node_id", _I), ("seq", _I), ("kind", _S), ("u1_v", _D), ("u2_v", _D),
                                    ("delta1_ref_m", _D), ("delta2_ref_m", _D), ("t_ns", _I)]),
}
BINARY_TOPICS: frozenset[str] = frozenset(CHANNELS)
MESSAGE_ENCODING = SCHEMA_ENCODING = "protobuf"


def file_descriptor() -> descriptor_pb2.FileDescriptorProto:
    """The proto3 file defining every binary channel's message (package `sea_hil`, all fields `optional`)."""
    fdp = descriptor_pb2.FileDescriptorProto(name=PROTO_FILE, package="sea_hil", syntax="proto3")
    for name, fields in CHANNELS.values():
        m = fdp.message_type.add(name=name)
        for i, (field, kind) in enumerate(fields):
            m.field.add(name=field, number=i + 1, type=_TYPES[kind], label=_F.LABEL_OPTIONAL, proto3_optional=True,
                        oneof_index=i, json_name=field)
            m.oneof_decl.add(name=f"_{field}")
    return fdp


def schema_data() -> bytes:
    """The MCAP schema record's data: a serialized FileDescriptorSet (what Foxglove's protobuf support reads)."""
    return descriptor_pb2.FileDescriptorSet(file=[file_descriptor()]).SerializeToString()


def schema_name(topic: str) -> str:
    return f"sea_hil.{CHANNELS[topic][0]}"


def _classes() -> dict[str, type[Message]]:
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file_descriptor())
    return {t: message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name(t))) for t in CHANNELS}


_CLASS = _classes()
_DOUBLES = {t: frozenset(f for f, k in fields if k == _D) for t, (_, fields) in CHANNELS.items()}


def message_class(topic: str) -> Callable[..., Message]:
    """The protobuf message class of binary channel `topic`, for payloads that need none of `encode`'s checks
    (the CAN tap's own, built from decoded frames: `cls(**payload).SerializeToString()` is what `encode` writes)."""
    return _CLASS[topic]


def encode(topic: str, payload: Mapping[str, Any]) -> bytes:
    """One message of binary channel `topic`; `RecordingError` for a field the channel does not have or a value of
    the wrong type (the check JSON's validation did)."""
    if None in payload.values():   # JSON's null: a double as NaN (read back as None), any other field absent
        doubles = _DOUBLES[topic]
        payload = {k: math.nan if v is None else v for k, v in payload.items() if v is not None or k in doubles}
    try:
        return _CLASS[topic](**payload).SerializeToString()
    except (TypeError, ValueError) as err:   # unknown field, wrong type
        raise RecordingError(f"{topic}: cannot encode {dict(payload)!r} as {schema_name(topic)}: {err}") from err


def decode(topic: str, data: bytes) -> dict[str, Any]:
    """The payload dict of one message (fields in number order, non-finite numbers as None); `RecordingError` when
    `data` is not a message of the channel."""
    try:
        msg = _CLASS[topic].FromString(data)
    except DecodeError as err:
        raise RecordingError(f"{topic}: undecodable {schema_name(topic)} message: {err}") from err
    return {f.name: None if isinstance(v, float) and not math.isfinite(v) else v for f, v in msg.ListFields()}

"""What one CAN frame becomes in a recording: a `/can/raw` message and, when the DBC accepts it, a decoded
`/can/feedback` or `/can/command` message. Pure (no I/O); used by the in-process recorder node and the recorder
process alike, so both write identical files.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import can

from protocol.can_codec import SeaCodec
from protocol.can_frames import CMD_BITS, FeedbackAngle, FeedbackJoint1, FeedbackJoint2, VoltageCmd
from protocol.errors import MalformedFrame


class RawFrame(NamedTuple):
    """The recorded facts of one frame (cheap to build, pickle and ship to another process)."""
    t_ns: int
    can_id: int
    dlc: int
    data: bytes
    is_extended: bool = False
    is_error: bool = False
    is_remote: bool = False
    is_fd: bool = False

    @classmethod
    def of(cls, t_ns: int, msg: can.Message) -> RawFrame:
        return cls(t_ns, msg.arbitration_id, msg.dlc, bytes(msg.data or b""), bool(msg.is_extended_id),
                   bool(msg.is_error_frame), bool(msg.is_remote_frame), bool(msg.is_fd))


def can_records(codec: SeaCodec, f: RawFrame) -> tuple[list[tuple[str, dict[str, Any]]], bool]:
    """((topic, payload) messages to record, rejected?) for one frame; rejected frames keep their `/can/raw`."""
    out: list[tuple[str, dict[str, Any]]] = [
        ("/can/raw", {"can_id": f.can_id, "dlc": f.dlc, "data_hex": f.data.hex(), "direction": "rx",
                      "is_extended": f.is_extended, "node_id": f.can_id >> CMD_BITS})]
    try:
        d = codec.decode_raw(f.can_id, f.data, f.dlc, is_extended=f.is_extended, is_error=f.is_error,
                             is_remote=f.is_remote, is_fd=f.is_fd)
    except MalformedFrame:
        return out, True
    if isinstance(d, VoltageCmd):
        out.append(("/can/command", {"node_id": d.node_id, "seq": d.seq, "kind": "voltage",
                                     "u1_v": d.voltage_v[0], "u2_v": d.voltage_v[1]}))
    elif isinstance(d, FeedbackAngle):
        out.append(("/can/feedback", {"node_id": d.node_id, "seq": d.seq, "t_us": d.t_us,
                                      "theta1_rad": d.theta_rad[0], "theta2_rad": d.theta_rad[1]}))
    elif isinstance(d, (FeedbackJoint1, FeedbackJoint2)):
        j = 1 if isinstance(d, FeedbackJoint1) else 2
        out.append(("/can/feedback", {"node_id": d.node_id, "seq": d.seq,
                                      f"omega{j}_rad_s": d.omega_rad_s, f"delta{j}_m": d.delta_m}))
    return out, False

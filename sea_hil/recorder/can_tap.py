"""What one CAN frame becomes in a recording: a `/can/raw` message and, when the DBC accepts it, a decoded
`/can/feedback` or `/can/command` message. Pure (no I/O); used by the in-process recorder node and the recorder
process alike (through `CanTap`, which also keeps the CAN counters), so both write identical files.

Missed frames: feedback and voltage frames carry an 8-bit `seq` that steps by one per sample, and CAN keeps the
order of one id's frames, so a forward step of n > 1 on one id means n - 1 frames of that id never reached the
recorder (`SeqGapCounter`). A repeat (step 0: a lockstep re-send) is not a gap. Limits: a loss of a multiple of 256
frames in a row of one id is invisible, frames lost after an id's last received frame are not seen, and a sender
that restarts its count (or skips a sample it did not answer) shows up as a gap too.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import can

from sea_hil.protocol.can_assembly import seq_gap
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import CMD_BITS, FeedbackAngle, FeedbackJoint1, FeedbackJoint2, VoltageCmd
from sea_hil.errors import MalformedFrame


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


class SeqGapCounter:
    """Frames missed per CAN id, from the rolling 8-bit `seq` of consecutive frames of that id (see module doc)."""

    def __init__(self) -> None:
        self._last: dict[int, int] = {}
        self.missed = 0

    def feed(self, can_id: int, seq: int) -> int:
        """Account one received frame of `can_id` carrying `seq`; -> frames of that id missed just before it."""
        prev, self._last[can_id] = self._last.get(can_id), seq
        gap = 0 if prev is None else max(seq_gap(prev, seq) - 1, 0)
        self.missed += gap
        return gap


class CanTap:
    """`can_records` plus the recorder's CAN counters: frames seen, rejected by the DBC, missed (seq gaps)."""

    def __init__(self, codec: SeaCodec | None = None) -> None:
        self.codec = codec or SeaCodec()
        self.gaps = SeqGapCounter()
        self.frames = self.rejected = 0

    def records(self, f: RawFrame) -> list[tuple[str, dict[str, Any]]]:
        """The (topic, payload) messages of one frame, counted."""
        out, rejected = can_records(self.codec, f)
        self.frames += 1
        self.rejected += rejected
        seq = out[1][1].get("seq") if len(out) > 1 else None   # the decoded record of a seq-carrying frame
        if isinstance(seq, int):
            self.gaps.feed(f.can_id, seq)
        return out

    def counters(self) -> dict[str, int]:
        return {"can_frames": self.frames, "can_rejected": self.rejected, "can_frames_missed": self.gaps.missed}

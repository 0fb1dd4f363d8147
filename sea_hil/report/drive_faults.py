"""Every latch of a drive's safe state in a session recording (summary.json `drive_faults`), read back from the
drives' own HEARTBEAT frames in `/can/raw` (`source: "can"`): what a real drive on can0 tells the bus too, so the
same code judges a session with the emulator and one with a real robot. A recording without a CAN tap (`sea-hil
record` without `--can`) takes the latches each edge counted from the heartbeats it received (`source: "edge"`, its
final `/stats` record): never both, so no latch counts twice.

The latch rule is sea_hil/drive_latches.py's (the edge's too). Times are the heartbeat's, so they carry the heartbeat
period (`can.heartbeat_rate_hz`, 10 Hz) as their resolution: `t_s` is seconds since the recording's first CAN frame
(the drive's own clock in lockstep; from the edge: since its first sample, on the sample clock). `clear_policy` says
who can end it (the edge's policy, `EdgeCore.answer` in controller/edge_core.py; the words: sea_hil/fault_explain.py):
a watchdog latch is cleared by the edge when setpoints are fresh again (real time; a lockstep session never clears),
a soft-limit latch or an e-stop needs the user. `after_session`: the latch began after the last measured sample (the
`/tracking` record of the largest cycle time `t_s`): in real time the edge stops commanding once setpoints stop and
the drive's watchdog takes the limb to its safe state, as designed; summary.json lists such a latch, the verdict does
not count it. An edge's record details its first `DETAILED` latches (`drive_latches` counts them all).

A cia402 session (docs/cia402.md) has no DBC heartbeat: a latch is read from the nodes' statusword TPDOs instead
(CiA 402 FAULT or FAULT REACTION ACTIVE; a statusword out of it ends the latch, as the fault reset does), its
flags from the EMCY codes the node sent since its last statusword outside FAULT, `node_id` the CANopen node's; the
frames are decoded as the bus configured them. Both profiles are read by `protocol.drive_state` (the live view's and
the ROS 2 export's reader too).
"""
from __future__ import annotations

from typing import Any

from sea_hil.drive_latches import LatchLog, edge_latch_entries, in_time_order, latch_entries
from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_frames import Heartbeat
from sea_hil.protocol.drive_state import DriveStateReader, drive_state_reader
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.recorder.session_config import canopen_decoder


def _drive_states(raw: list[RecordedMessage], reader: DriveStateReader) -> list[tuple[int, Heartbeat]]:
    """The recording's frames that report a drive state, as the latch reader's (time, state) pairs; a frame that is
    not one (or is malformed) is passed over: the recording keeps it."""
    out: list[tuple[int, Heartbeat]] = []
    for m in raw:
        p = m.payload
        try:
            hb = reader.on_frame(int(p["can_id"]), bytes.fromhex(p["data_hex"]), int(p["dlc"]),
                                 extended=bool(p.get("is_extended")), fd=bool(p.get("is_fd")))
        except (MalformedFrame, KeyError, TypeError, ValueError):
            continue
        if hb is not None:
            out.append((m.log_time_ns, hb))
    return out


def drive_faults(data: SessionData) -> list[dict[str, Any]]:
    """Every safe-state latch of every drive of the recording, in time order (see the module docstring); without a
    CAN tap, those the edges counted (`edge_latches`)."""
    raw = data.messages.get("/can/raw", [])
    if not raw:
        return edge_latches(data)
    states = _drive_states(raw, drive_state_reader(canopen_decoder(data)))
    t0_ns = raw[0].log_time_ns
    tracking = data.messages.get("/tracking", [])
    last = max(tracking, key=lambda m: m.payload.get("t_s", float("-inf")), default=None)
    end_ns = last.log_time_ns if last is not None else None   # the last measured sample (largest cycle time)
    latches = LatchLog()
    for t_ns, hb in states:
        latches.on_heartbeat(t_ns, hb)
    return in_time_order(latch_entries(latches.latches, t0_ns, end_ns, "can"))


def edge_latches(data: SessionData) -> list[dict[str, Any]]:
    """The latches each edge counted from the heartbeats it received (its final `/stats` record,
    sea_hil/drive_latches.py): a recording without a CAN tap (`sea-hil record` without `--can`). `t_s` counts from
    the edge's first sample; `after_session` maps the edge's sample time onto the controller's time axis (a state's
    sample time against its tracking record's `t_s`)."""
    finals = {}
    for m in data.messages.get("/stats", []):
        if m.payload.get("final") and m.payload.get("node", "edge") == "edge":
            finals[int(m.payload.get("node_id", 1))] = m.payload     # the last record per drive
    return edge_latch_entries(finals.values(), _cycle_end_sample_ns(data))


def cycle_origin_ns(data: SessionData) -> int | None:
    """The sample time (drive clock) of the controller's cycle time 0: the first tracking record whose state the
    recording has, its state's `sample_t_ns` less its `t_s` (None without such a state). The one anchor of the
    controller's time axis on the sample clock (the session summary's phases too)."""
    sample_ns: dict[Any, int] = {}
    for m in data.messages.get("/zenoh/state", []):   # a state's first record (an edge restarted counts seqs anew)
        if m.payload.get("sample_t_ns") is not None:
            sample_ns.setdefault(m.payload.get("seq"), int(m.payload["sample_t_ns"]))
    anchor = next((m.payload for m in data.messages.get("/tracking", [])
                   if m.payload.get("state_seq") in sample_ns), None)
    return None if anchor is None else sample_ns[anchor["state_seq"]] - round(anchor["t_s"] * 1e9)


def _cycle_end_sample_ns(data: SessionData) -> int | None:
    """The sample time (drive clock) of the last measured sample: the controller's largest cycle time `t_s` on the
    sample clock (None without an anchor, `cycle_origin_ns`)."""
    t0_ns = cycle_origin_ns(data)
    return None if t0_ns is None else \
        t0_ns + round(max(m.payload["t_s"] for m in data.messages["/tracking"]) * 1e9)

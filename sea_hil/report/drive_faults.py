"""Every latch of a drive's safe state in a session recording (summary.json `drive_faults`), read back from the
drives' own HEARTBEAT frames in `/can/raw`: what a real drive on can0 tells the bus too, so the same code judges a
session with the emulator and one with a real robot.

A latch starts at the first heartbeat in FAULT or ESTOP after one that was not (or at the first heartbeat) and ends
at the next heartbeat out of it (a CLEAR_ERRORS took it back to INIT) or at the recording's last heartbeat (still
latched). Times are the heartbeat's, so they carry the heartbeat period (`can.heartbeat_rate_hz`, 10 Hz) as their
resolution: `t_s` is seconds since the recording's first CAN frame (the drive's own clock in lockstep). The flags
are every error flag the drive reported during the latch; `clear_policy` says who can end it (the edge's policy,
controller/edge_command.py): a watchdog latch is cleared by the edge when setpoints are fresh again (real time; a
lockstep session never clears), a soft-limit latch or an e-stop needs the user.
"""
from __future__ import annotations

from typing import Any

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import CMD_MASK, LIMIT_FLAGS, DriverState, ErrorFlags, Heartbeat
from sea_hil.recorder.reader import SessionData

SAFE = (DriverState.FAULT, DriverState.ESTOP)
POLICY_EDGE_CLEARS = "the edge clears it (CLEAR_ERRORS) once setpoints are fresh again (real time; never in lockstep)"
POLICY_USER = "needs the user: fix the cause, then CLEAR_ERRORS (the edge never clears a soft-limit fault or an e-stop)"


def flag_names(flags: ErrorFlags | int) -> list[str]:
    """The names of the set error flags, in bit order."""
    return [f.name or "" for f in ErrorFlags if f & flags]


def clear_policy(state: DriverState, flags: ErrorFlags | int) -> str:
    """Who ends a latch in `state` with `flags` (see the module docstring)."""
    if state is DriverState.ESTOP or flags & (LIMIT_FLAGS | ErrorFlags.ESTOP):
        return POLICY_USER
    return POLICY_EDGE_CLEARS


def _heartbeats(data: SessionData, codec: SeaCodec, hb_cmd: int) -> list[tuple[int, Heartbeat]]:
    out = []
    for m in data.messages.get("/can/raw", []):
        p = m.payload
        if int(p.get("can_id", -1)) & CMD_MASK != hb_cmd:
            continue
        try:
            frame = codec.decode_raw(int(p["can_id"]), bytes.fromhex(p["data_hex"]), int(p["dlc"]),
                                     is_extended=bool(p.get("is_extended")), is_fd=bool(p.get("is_fd")))
        except (MalformedFrame, KeyError, ValueError):
            continue
        if isinstance(frame, Heartbeat):
            out.append((m.log_time_ns, frame))
    return out


def drive_faults(data: SessionData) -> list[dict[str, Any]]:
    """Every safe-state latch of every drive of the recording, in time order (see the module docstring)."""
    codec = SeaCodec(fd=None)
    hb_cmd = codec._layout_of(Heartbeat).cmd_id   # noqa: SLF001  (the DBC's HEARTBEAT command id)
    raw = data.messages.get("/can/raw", [])
    if not raw:
        return []
    t0_ns = raw[0].log_time_ns
    open_: dict[int, dict[str, Any]] = {}
    last_ns: dict[int, int] = {}
    latches: list[dict[str, Any]] = []
    for t_ns, hb in _heartbeats(data, codec, hb_cmd):
        last_ns[hb.node_id] = t_ns
        cur = open_.get(hb.node_id)
        if hb.state in SAFE:
            if cur is None:
                cur = open_[hb.node_id] = {"node_id": hb.node_id, "t_ns": t_ns, "state": hb.state, "flags": hb.flags}
            else:
                cur["flags"] |= hb.flags
                if hb.state is DriverState.ESTOP:
                    cur["state"] = hb.state
        elif cur is not None:
            latches.append(_latch(cur, t_ns, t0_ns, cleared=True))
            del open_[hb.node_id]
    latches += [_latch(cur, last_ns[n], t0_ns, cleared=False) for n, cur in open_.items()]
    return sorted(latches, key=lambda e: (e["t_s"], e["node_id"]))


def _latch(cur: dict[str, Any], end_ns: int, t0_ns: int, *, cleared: bool) -> dict[str, Any]:
    state, flags = cur["state"], ErrorFlags(cur["flags"])
    return {"node_id": int(cur["node_id"]), "t_s": (cur["t_ns"] - t0_ns) * 1e-9, "state": state.name,
            "flags": flag_names(flags), "in_fault_s": (end_ns - cur["t_ns"]) * 1e-9, "cleared": cleared,
            "clear_policy": clear_policy(state, flags)}

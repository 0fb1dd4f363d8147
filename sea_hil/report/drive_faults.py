"""Every latch of a drive's safe state in a session recording (summary.json `drive_faults`), read back from the
drives' own HEARTBEAT frames in `/can/raw`: what a real drive on can0 tells the bus too, so the same code judges a
session with the emulator and one with a real robot.

A latch starts at the first heartbeat in FAULT or ESTOP after one that was not (or at the first heartbeat) and ends
at the next heartbeat out of it (a CLEAR_ERRORS took it back to INIT) or at the recording's last heartbeat (still
latched). Times are the heartbeat's, so they carry the heartbeat period (`can.heartbeat_rate_hz`, 10 Hz) as their
resolution: `t_s` is seconds since the recording's first CAN frame (the drive's own clock in lockstep). The flags
are every error flag the drive reported during the latch; `clear_policy` says who can end it (the edge's policy,
`EdgeCore.answer` in controller/edge_core.py; the words: sea_hil/fault_explain.py): a watchdog latch is cleared by
the edge when setpoints are fresh again (real time; a lockstep session never clears), a soft-limit latch or an
e-stop needs the user. `after_session`: the latch began after the last measured sample (the `/tracking` record of the largest cycle
time `t_s`): in real time the edge stops commanding once setpoints stop and the drive's watchdog takes the limb
to its safe state, as designed; summary.json lists such a latch, the verdict does not count it.

A cia402 session (docs/cia402.md) has no DBC heartbeat: a latch is read from the nodes' statusword TPDOs instead
(CiA 402 FAULT or FAULT REACTION ACTIVE; a statusword out of it ends the latch, as the fault reset does), its
flags from the EMCY codes the node sent since its last statusword outside FAULT (`EMCY_CODES` back to the drive's
error flags), `node_id` the CANopen node's. The frames are decoded as the bus configured them
(`protocol.cia402_decode`).
"""
from __future__ import annotations

from typing import Any

from sea_hil.errors import MalformedFrame
from sea_hil.fault_explain import SAFE, clear_policy, flag_names
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import CMD_MASK, DriverState, ErrorFlags, Heartbeat
from sea_hil.protocol.cia402_decode import Cia402Decoder
from sea_hil.protocol.cia402_od import EMCY_CODES
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.recorder.session_config import canopen_decoder

FLAG_OF_CODE = {code: flag for flag, code in EMCY_CODES.items()}
CIA402_FAULT_STATES = (0x08, 0x0F)   # statusword & 0x4F: FAULT, FAULT REACTION ACTIVE (CiA 402)


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


def _cia402_states(raw: list[RecordedMessage], decoder: Cia402Decoder) -> list[tuple[int, Heartbeat]]:
    """A cia402 recording's statusword TPDOs as the latch reader's (time, state) pairs: FAULT with the flags of the
    node's EMCYs since its last statusword outside FAULT, else RUNNING (module docstring)."""
    out: list[tuple[int, Heartbeat]] = []
    flags: dict[int, ErrorFlags] = {}
    for m in raw:
        p = m.payload
        try:
            d = decoder.decode(int(p["can_id"]), bytes.fromhex(p["data_hex"]), extended=bool(p.get("is_extended")))
        except (KeyError, TypeError, ValueError):
            continue
        if d.kind == "EMCY":
            flags[d.node_id] = flags.get(d.node_id, ErrorFlags(0)) | FLAG_OF_CODE.get(d.values.get("error_code", 0),
                                                                                       ErrorFlags(0))
        elif "statusword" in d.values:
            fault = d.values["statusword"] & 0x4F in CIA402_FAULT_STATES
            hb = Heartbeat(d.node_id, DriverState.FAULT if fault else DriverState.RUNNING,
                           flags.get(d.node_id, ErrorFlags(0)) if fault else ErrorFlags(0), 0, 0, 0)
            if not fault:
                flags.pop(d.node_id, None)
            out.append((m.log_time_ns, hb))
    return out


def drive_faults(data: SessionData) -> list[dict[str, Any]]:
    """Every safe-state latch of every drive of the recording, in time order (see the module docstring)."""
    raw = data.messages.get("/can/raw", [])
    if not raw:
        return []
    decoder = canopen_decoder(data)
    if decoder is not None:
        states = _cia402_states(raw, decoder)
    else:
        hb_cmd = load_database().get_message_by_name("HEARTBEAT").frame_id & CMD_MASK
        states = _heartbeats(data, SeaCodec(fd=None), hb_cmd)
    t0_ns = raw[0].log_time_ns
    tracking = data.messages.get("/tracking", [])
    last = max(tracking, key=lambda m: m.payload.get("t_s", float("-inf")), default=None)
    end_ns = last.log_time_ns if last is not None else None   # the last measured sample (largest cycle time)
    open_: dict[int, dict[str, Any]] = {}
    last_ns: dict[int, int] = {}
    latches: list[dict[str, Any]] = []
    for t_ns, hb in states:
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
            latches.append(_latch(cur, t_ns, t0_ns, end_ns, cleared=True))
            del open_[hb.node_id]
    latches += [_latch(cur, last_ns[n], t0_ns, end_ns, cleared=False) for n, cur in open_.items()]
    return sorted(latches, key=lambda e: (e["t_s"], e["node_id"]))


def _latch(cur: dict[str, Any], until_ns: int, t0_ns: int, session_end_ns: int | None, *, cleared: bool
           ) -> dict[str, Any]:
    state, flags = cur["state"], ErrorFlags(cur["flags"])
    after = session_end_ns is not None and cur["t_ns"] > session_end_ns
    return {"node_id": int(cur["node_id"]), "t_s": (cur["t_ns"] - t0_ns) * 1e-9, "state": state.name,
            "flags": flag_names(flags), "in_fault_s": (until_ns - cur["t_ns"]) * 1e-9, "cleared": cleared,
            "clear_policy": clear_policy(state, flags), "after_session": after}

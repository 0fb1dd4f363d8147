"""What one CAN frame becomes in a recording: a `/can/raw` message and, when the DBC accepts it, a decoded
`/can/feedback` or `/can/command` message. Pure (no I/O); used by the in-process recorder node and the recorder
process alike (through `CanTap`, which also keeps the CAN counters), so both write identical files.

Time (`sea_hil.recorder.clock`): with `time_base="wall"` a frame is logged at its bus timestamp, with "sample" at the
drive's sample time (its node's latest FEEDBACK_ANGLE `t_us`, unwrapped). The MCAP `sequence` of a frame's messages
is the frame's own 8-bit `seq` (0 for frames without one). Faults go to `/log/faults` (`foxglove.Log`) as well: a
driver's state or error flags changing (HEARTBEAT), a frame the DBC refuses, frames missed; with the session's
config (`configure`), once per latch of a drive's safe state the limit, the measured value and who clears it.

The cia402 profile (a session config with `[can] profile = "cia402"`, `configure`): every frame (NMT, SYNC,
heartbeat, EMCY, SDO, PDOs) goes to `/can/raw` with its CANopen node id (`node_id`: the id's low 7 bits, 0 for NMT
and SYNC), nothing is decoded with the DBC; the target voltages of each limb's two RPDOs (object 0x2000, decoded by
`protocol.cia402_decode` with the mapping the nodes have at the time) make one `/can/command` (`node_id`: the hip
node's, `seq`: the number of SYNCs seen, mod 256), so the summary's voltages and the recording's completeness check
read it as in the sea profile. Sample time base: one `can.feedback_rate_hz` period per SYNC (COB-ID 0x080, the
dictionary's default) seen on the frame's bus, the drive's lockstep clock (frames before the first SYNC: 0), given
by the bus's recorder node (`stamp`): a frame is recorded at the time it comes with.

Missed frames: the driver's feedback frames carry an 8-bit `seq` that steps by one per sample it integrates (a
skipped deadline is no sample), and CAN keeps the order of one id's frames, so a forward step of n > 1 on one id
means n - 1 frames of that id never reached the recorder (`SeqGapCounter`, `can_frames_missed`). A repeat (step 0: a
lockstep re-send) is not a gap. A VOLTAGE_CMD's `seq` is the sample it answers, and a real-time edge behind its
samples answers only the freshest, so its gaps (`can_command_gaps`) are lost frames or unanswered samples: counted
apart, never called lost (the recording's `can_command` channel checks those frames against the edge's own count,
summary.json `completeness`). Limits: a loss of a multiple of 256 frames in a row of one id is invisible, frames lost
after an id's last received frame are not seen, and a driver that restarts its count shows up as a gap too.
"""
from __future__ import annotations

import logging
import tomllib
from typing import Any, NamedTuple

import can

from sea_hil.config.loader import config_from_dict
from sea_hil.errors import MalformedFrame, SeaHilError
from sea_hil.fault_explain import LatchWatch, Measured, latch_level
from sea_hil.protocol.can_assembly import seq_gap
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import (
    CMD_BITS,
    DriverState,
    ErrorFlags,
    Feedback,
    FeedbackAngle,
    FeedbackJoint1,
    FeedbackJoint2,
    Heartbeat,
    VoltageCmd,
)
from sea_hil.protocol.cia402_decode import Cia402Decoder, decoder_for
from sea_hil.protocol.cia402_od import SYNC_DEFAULT
from sea_hil.recorder.clock import SampleClock, TimeBase, check_time_base
from sea_hil.recorder.well_known import LogLevel, log_message

_FD_FIELDS = (("theta", "theta_rad", "rad"), ("omega", "omega_rad_s", "rad_s"), ("delta", "delta_m", "m"),
              ("nut_vel", "nut_vel_m_s", "m_s"))


class Record(NamedTuple):
    """One message to write: what the taps hand to `SessionRecorder.submit(*record)`."""
    topic: str
    log_time_ns: int
    publish_time_ns: int
    payload: dict[str, Any]
    sequence: int = 0


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


def can_records(codec: SeaCodec, f: RawFrame) -> tuple[list[tuple[str, dict[str, Any]]], bool, Any]:
    """((topic, payload) messages to record, rejected?, the decoded frame or the DBC's error) for one frame;
    rejected frames keep their `/can/raw`."""
    raw = {"can_id": f.can_id, "dlc": f.dlc, "data_hex": f.data.hex(), "direction": "rx",
           "is_extended": f.is_extended, "node_id": f.can_id >> CMD_BITS}
    if f.is_fd:
        raw["is_fd"] = True
    out: list[tuple[str, dict[str, Any]]] = [("/can/raw", raw)]
    try:
        d = codec.decode_raw(f.can_id, f.data, f.dlc, is_extended=f.is_extended, is_error=f.is_error,
                             is_remote=f.is_remote, is_fd=f.is_fd)
    except MalformedFrame as err:
        return out, True, err
    if isinstance(d, VoltageCmd):
        out.append(("/can/command", {"node_id": d.node_id, "seq": d.seq, "kind": "voltage",
                                     "u1_v": d.voltage_v[0], "u2_v": d.voltage_v[1]}))
    elif isinstance(d, FeedbackAngle):
        out.append(("/can/feedback", {"node_id": d.node_id, "seq": d.seq, "t_us": d.t_us,
                                      "theta1_rad": d.theta_rad[0], "theta2_rad": d.theta_rad[1]}))
    elif isinstance(d, Feedback):   # CAN FD: the whole sample in one frame
        out.append(("/can/feedback", {"node_id": d.node_id, "seq": d.seq, "t_us": d.t_us,
                                      **{f"{k}{j + 1}_{u}": getattr(d, a)[j] for k, a, u in _FD_FIELDS
                                         for j in (0, 1)}}))
    elif isinstance(d, (FeedbackJoint1, FeedbackJoint2)):
        j = 1 if isinstance(d, FeedbackJoint1) else 2
        out.append(("/can/feedback", {"node_id": d.node_id, "seq": d.seq, f"omega{j}_rad_s": d.omega_rad_s,
                                      f"delta{j}_m": d.delta_m, f"nut_vel{j}_m_s": d.nut_vel_m_s}))
    return out, False, d


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
    """`can_records` plus the recorder's CAN counters (frames seen, rejected by the DBC, missed from seq gaps), the
    log time of each message (`time_base`) and the `/log` messages of faults."""

    def __init__(self, codec: SeaCodec | None = None, time_base: TimeBase = "wall") -> None:
        self.codec = codec or SeaCodec(fd=None)
        self.time_base = check_time_base(time_base)
        self.clock = SampleClock()
        self.gaps = SeqGapCounter()           # the driver's feedback frames: a gap is a frame lost (module doc)
        self.command_gaps = SeqGapCounter()   # VOLTAGE_CMD frames: lost, or samples the edge did not answer
        self.frames = self.rejected = 0
        self._driver: dict[int, tuple[DriverState, ErrorFlags]] = {}
        self.latches: LatchWatch | None = None   # `configure`: the session's drive limits explain each latch
        self.canopen: Cia402Decoder | None = None  # `configure`: a cia402 session (module docstring)
        self._pairs: tuple[tuple[int, int], ...] = ()
        self._volts: dict[int, int] = {}           # cia402: node -> its newest target voltage (mV) not yet paired
        self._syncs = 0                            # cia402: SYNCs decoded (the /can/command seq)
        self._bus_syncs = 0                        # cia402, sample time base: SYNCs stamped (`stamp`)
        self._period_ns = 0

    def configure(self, config_toml: str) -> None:
        """The session's config (its attached config.toml): from now on a drive's latch gets one `/log/faults` line
        naming the limit, the measured value and who clears it (sea_hil/fault_explain.py). A config that does not
        load leaves the plain state-change lines."""

        try:
            cfg = config_from_dict(tomllib.loads(config_toml))
        except (tomllib.TOMLDecodeError, SeaHilError):
            return
        if cfg.can.profile == "cia402":
            ids = cfg.can.cia402.node_ids
            self.canopen = decoder_for(cfg)
            self._pairs = tuple((ids[i], ids[i + 1]) for i in range(0, len(ids), 2))
            self._period_ns = round(1e9 / cfg.can.feedback_rate_hz)
            return
        self.latches = LatchWatch(cfg.safety.drive if cfg.safety.drive.enabled else None,
                                  (cfg.plant.k1_n_per_m, cfg.plant.k2_n_per_m))

    def records(self, f: RawFrame) -> list[Record]:
        """The messages of one frame, counted and timed."""
        if self.canopen is not None:
            return self._canopen_records(self.canopen, f)
        out, rejected, decoded = can_records(self.codec, f)
        self.frames += 1
        self.rejected += rejected
        if isinstance(decoded, (FeedbackAngle, Feedback)):
            self.clock.on_feedback(decoded.node_id, decoded.t_us)
        t_ns = f.t_ns if self.time_base == "wall" else self.clock.node_ns(f.can_id >> CMD_BITS)
        seq = getattr(decoded, "seq", 0)
        recs = [Record(topic, t_ns, t_ns, payload, seq) for topic, payload in out]
        logs: list[tuple[LogLevel, str, str]] = []
        if rejected:
            logs.append((LogLevel.WARNING, "recorder", f"CAN frame 0x{f.can_id:03X} rejected by the DBC: {decoded}"))
        elif isinstance(decoded, VoltageCmd):   # its seq is the sample it answers: a gap may be an unanswered one
            self.command_gaps.feed(f.can_id, decoded.seq)
        elif len(out) > 1 and isinstance(out[1][1].get("seq"), int):   # the driver's own numbering of its samples
            missed = self.gaps.feed(f.can_id, out[1][1]["seq"])
            if missed:
                logs.append((LogLevel.WARNING, "recorder", f"CAN id 0x{f.can_id:03X}: {missed} frame(s) missed"))
        if isinstance(decoded, Heartbeat):
            logs.extend(self._driver_change(decoded))
            line = self.latches.on_heartbeat(decoded) if self.latches is not None else None
            if line is not None:   # ERROR when it needs the user, WARNING when the edge clears it
                level = LogLevel.ERROR if latch_level(decoded) >= logging.ERROR else LogLevel.WARNING
                logs.append((level, f"driver{decoded.node_id}", line))
        elif self.latches is not None and isinstance(decoded, (FeedbackAngle, Feedback)):
            self.latches.feedback(decoded.node_id, decoded.theta_rad,
                                  *((decoded.omega_rad_s, decoded.delta_m) if isinstance(decoded, Feedback) else ()))
        elif self.latches is not None and isinstance(decoded, (FeedbackJoint1, FeedbackJoint2)):
            m = self.latches.measured.setdefault(decoded.node_id, Measured())
            j = 0 if isinstance(decoded, FeedbackJoint1) else 1
            w, d = list(m.omega_rad_s or (0.0, 0.0)), list(m.delta_m or (0.0, 0.0))
            w[j], d[j] = decoded.omega_rad_s, decoded.delta_m
            m.omega_rad_s, m.delta_m = (w[0], w[1]), (d[0], d[1])
        recs.extend(Record("/log/faults", t_ns, t_ns, log_message(t_ns, lv, who, text), seq) for lv, who, text in logs)
        return recs

    def stamp(self, t_ns: int, can_id: int, is_extended: bool = False) -> int:
        """The log time of a frame received at `t_ns` on this tap's bus: `t_ns`, except in a cia402 session on the
        sample time base: the bus's SYNCs so far (this one included) times the SYNC period. Called by the recorder
        node of each bus, so that every bus keeps its own clock when several buses share one recorder process."""
        if self.canopen is None or self.time_base == "wall":
            return t_ns
        if can_id == SYNC_DEFAULT and not is_extended:
            self._bus_syncs += 1
        return self._bus_syncs * self._period_ns

    def _canopen_records(self, decoder: Cia402Decoder, f: RawFrame) -> list[Record]:
        """A cia402 session's frame: `/can/raw`, and `/can/command` when it completes a limb's pair of target
        voltages (module docstring)."""
        self.frames += 1
        d = decoder.decode(f.can_id, f.data, remote=f.is_remote, extended=f.is_extended or f.is_error)
        if d.kind == "SYNC":
            self._syncs += 1
        t_ns = f.t_ns   # stamped by the bus's recorder node (`stamp`)
        raw = {"can_id": f.can_id, "dlc": f.dlc, "data_hex": f.data.hex(), "direction": "rx",
               "is_extended": f.is_extended, "node_id": d.node_id}
        out = [Record("/can/raw", t_ns, t_ns, raw)]
        mv = d.values.get("target_voltage")
        if mv is None or not d.kind.startswith("RPDO"):
            return out
        self._volts[d.node_id] = mv
        for hip, knee in self._pairs:
            if d.node_id == knee and hip in self._volts:
                seq = self._syncs & 0xFF
                cmd = {"node_id": hip, "seq": seq, "kind": "voltage", "u1_v": self._volts.pop(hip) * 1e-3,
                       "u2_v": self._volts.pop(knee) * 1e-3}
                out.append(Record("/can/command", t_ns, t_ns, cmd, seq))
        return out

    def _driver_change(self, hb: Heartbeat) -> list[tuple[LogLevel, str, str]]:
        """A log line when a driver's state or error flags differ from its previous heartbeat's."""
        now, before = (hb.state, hb.flags), self._driver.get(hb.node_id)
        self._driver[hb.node_id] = now
        if now == before:
            return []
        level = (LogLevel.ERROR if hb.state in (DriverState.FAULT, DriverState.ESTOP)
                 else LogLevel.WARNING if hb.flags else LogLevel.INFO)
        flags = "|".join(f.name or "" for f in ErrorFlags if f & hb.flags) or "none"
        return [(level, f"driver{hb.node_id}", f"driver {hb.node_id}: {hb.state.name}, error flags {flags}, "
                                               f"rejected frames {hb.rejected_frames}, overruns {hb.overruns}")]

    def counters(self) -> dict[str, int]:
        return {"can_frames": self.frames, "can_rejected": self.rejected, "can_frames_missed": self.gaps.missed,
                "can_command_gaps": self.command_gaps.missed}

"""What one CAN frame becomes in a recording: a `/can/raw` message and, when the DBC accepts it, a decoded
`/can/feedback` or `/can/command` message. Pure (no I/O); used by the in-process recorder node and the recorder
process alike (through `CanTap`, which also keeps the CAN counters), so both write identical files. `CanTap.encode`
is the recorder's hot path: a batch of frames straight to encoded messages (the protobuf channels serialized from
the decoded frame, `/can/raw` from cached pieces around its data), with no payload dict per message.

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
from binascii import hexlify
from collections.abc import Callable, Iterable, Sequence
from typing import Any, NamedTuple

import can

from sea_hil.config.loader import config_from_dict
from sea_hil.errors import MalformedFrame, SeaHilError
from sea_hil.fault_explain import LatchWatch, latch_level
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
from sea_hil.recorder import binary
from sea_hil.recorder.clock import SampleClock, TimeBase, check_time_base
from sea_hil.recorder.schemas import message_bytes, message_payload
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


Encoded = tuple[str, int, int, bytes, int]
"""One message ready for the file: (topic, log time, publish time, encoded data, sequence), what
`SessionRecorder.write_encoded` takes."""

_RAW, _FEEDBACK, _COMMAND = "/can/raw", "/can/feedback", "/can/command"
_RAW_TEMPLATES = 4096
_Add = Callable[[Encoded], None]


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
    """What frames become in the file (`encode`, the encoded messages; `records`, the same read back as payload
    dicts), the recorder's CAN counters (frames seen, rejected by the DBC, missed from seq gaps), the log time of
    each message (`time_base`) and the `/log` messages of faults."""

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
        # the tap's own payloads need none of `binary.encode`'s checks: serialized as they are
        self._raw, self._feedback = binary.message_class(_RAW), binary.message_class(_FEEDBACK)
        self._command = binary.message_class(_COMMAND)
        self._raw_templates: dict[tuple[int, int, int, bool, bool], tuple[bytes, bytes]] = {}
        # decoded frame type -> what it adds beside its /can/raw (other types: nothing)
        self._handlers: dict[type, Callable[[Any, int, int, int, _Add], None]] = {
            FeedbackAngle: self._on_angle, FeedbackJoint1: self._on_joint1, FeedbackJoint2: self._on_joint2,
            Feedback: self._on_fd, VoltageCmd: self._on_command, Heartbeat: self._on_heartbeat}
        # with `latches`: per node the newest feedback values, which a latch's line reports as measured
        self._theta: dict[int, tuple[float, float]] = {}
        self._omega: dict[int, list[float]] = {}
        self._delta: dict[int, list[float]] = {}

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
        """The messages of one frame, counted and timed, with their payloads as a reader decodes them (the dicts
        of the schemas, `sea_hil.recorder.schemas`): `encode` read back."""
        return [Record(topic, log, pub, message_payload(topic, data), seq)
                for topic, log, pub, data, seq in self.encode([f])]

    def encode(self, frames: Iterable[Sequence[Any]]) -> list[Encoded]:
        """The messages of many frames (`RawFrame`s or plain tuples of their fields), counted, timed and encoded
        as the file holds them: the recorder's hot path (one pass; per frame its bytes, no payload objects)."""
        if self.canopen is not None:
            return [(r.topic, r.log_time_ns, r.publish_time_ns, message_bytes(r.topic, r.payload), r.sequence)
                    for f in frames for r in self._canopen_records(self.canopen, RawFrame(*f))]
        out: list[Encoded] = []
        add, decode, handlers, raws = out.append, self.codec.decode_raw, self._handlers, self._raw_templates
        wall, clock = self.time_base == "wall", self.clock
        for t_ns, can_id, dlc, data, ext, err, rem, fd in frames:
            self.frames += 1
            key = (can_id, dlc, len(data), ext, fd)
            tpl = raws.get(key) or self._raw_template(key)
            raw = tpl[0] + hexlify(data) + tpl[1]
            try:
                d = decode(can_id, data, dlc, is_extended=ext, is_error=err, is_remote=rem, is_fd=fd)
            except MalformedFrame as bad:
                self.rejected += 1
                t = t_ns if wall else clock.node_ns(can_id >> CMD_BITS)
                add((_RAW, t, t, raw, 0))
                self._log(add, t, 0, LogLevel.WARNING, "recorder",
                          f"CAN frame 0x{can_id:03X} rejected by the DBC: {bad}")
                continue
            if not wall:
                if isinstance(d, (FeedbackAngle, Feedback)):
                    clock.on_feedback(d.node_id, d.t_us)
                t_ns = clock.node_ns(can_id >> CMD_BITS)
            seq = getattr(d, "seq", 0)
            add((_RAW, t_ns, t_ns, raw, seq))
            handler = handlers.get(type(d))
            if handler is not None:
                handler(d, can_id, t_ns, seq, add)
        return out

    def _raw_template(self, key: tuple[int, int, int, bool, bool]) -> tuple[bytes, bytes]:
        """The `/can/raw` message of a frame with this (id, DLC, data length, extended, FD) around its data: the
        encoding up to `data_hex`'s characters, and after them. A protobuf message is its fields' encodings in
        field order, so head + the hex digits + tail is what the whole message serializes to
        (tests/test_recording_binary.py). At most `_RAW_TEMPLATES` are kept (a bus of random ids cannot grow it)."""
        can_id, dlc, n, ext, fd = key
        head = self._raw(can_id=can_id, dlc=dlc, data_hex="0" * 2 * n).SerializeToString()[:-2 * n or None]
        tail = self._raw(direction="rx", is_extended=ext, node_id=can_id >> CMD_BITS,
                         **({"is_fd": True} if fd else {})).SerializeToString()
        if len(self._raw_templates) >= _RAW_TEMPLATES:
            self._raw_templates.clear()
        self._raw_templates[key] = head, tail
        return head, tail

    def _on_angle(self, d: FeedbackAngle, can_id: int, t: int, seq: int, add: _Add) -> None:
        add((_FEEDBACK, t, t, self._feedback(node_id=d.node_id, seq=seq, t_us=d.t_us, theta1_rad=d.theta_rad[0],
                                             theta2_rad=d.theta_rad[1]).SerializeToString(), seq))
        self._feedback_gap(can_id, t, seq, add)
        if self.latches is not None:
            self._theta[d.node_id] = d.theta_rad

    def _on_joint1(self, d: FeedbackJoint1, can_id: int, t: int, seq: int, add: _Add) -> None:
        add((_FEEDBACK, t, t, self._feedback(node_id=d.node_id, seq=seq, omega1_rad_s=d.omega_rad_s,
                                             delta1_m=d.delta_m, nut_vel1_m_s=d.nut_vel_m_s).SerializeToString(), seq))
        self._feedback_gap(can_id, t, seq, add)
        if self.latches is not None:
            self._joint(d.node_id, 0, d.omega_rad_s, d.delta_m)

    def _on_joint2(self, d: FeedbackJoint2, can_id: int, t: int, seq: int, add: _Add) -> None:
        add((_FEEDBACK, t, t, self._feedback(node_id=d.node_id, seq=seq, omega2_rad_s=d.omega_rad_s,
                                             delta2_m=d.delta_m, nut_vel2_m_s=d.nut_vel_m_s).SerializeToString(), seq))
        self._feedback_gap(can_id, t, seq, add)
        if self.latches is not None:
            self._joint(d.node_id, 1, d.omega_rad_s, d.delta_m)

    def _on_fd(self, d: Feedback, can_id: int, t: int, seq: int, add: _Add) -> None:   # CAN FD: a whole sample
        fields = {f"{k}{j + 1}_{u}": getattr(d, a)[j] for k, a, u in _FD_FIELDS for j in (0, 1)}
        add((_FEEDBACK, t, t, self._feedback(node_id=d.node_id, seq=seq, t_us=d.t_us, **fields).SerializeToString(),
             seq))
        self._feedback_gap(can_id, t, seq, add)
        if self.latches is not None:
            self._theta[d.node_id] = d.theta_rad
            self._joint(d.node_id, 0, d.omega_rad_s[0], d.delta_m[0])
            self._joint(d.node_id, 1, d.omega_rad_s[1], d.delta_m[1])

    def _on_command(self, d: VoltageCmd, can_id: int, t: int, seq: int, add: _Add) -> None:
        add((_COMMAND, t, t, self._command(node_id=d.node_id, seq=seq, kind="voltage", u1_v=d.voltage_v[0],
                                           u2_v=d.voltage_v[1]).SerializeToString(), seq))
        self.command_gaps.feed(can_id, seq)   # its seq is the sample it answers: a gap may be an unanswered one

    def _feedback_gap(self, can_id: int, t: int, seq: int, add: _Add) -> None:
        """The driver's numbering of its samples: a gap is frames lost (module docstring)."""
        missed = self.gaps.feed(can_id, seq)
        if missed:
            self._log(add, t, seq, LogLevel.WARNING, "recorder", f"CAN id 0x{can_id:03X}: {missed} frame(s) missed")

    def _joint(self, node_id: int, j: int, omega_rad_s: float, delta_m: float) -> None:
        """One joint's newest velocity and deflection (the other joint's stay; 0 before any)."""
        w = self._omega.get(node_id)
        if w is None:
            w = self._omega[node_id] = [0.0, 0.0]
            self._delta[node_id] = [0.0, 0.0]
        w[j] = omega_rad_s
        self._delta[node_id][j] = delta_m

    def _on_heartbeat(self, hb: Heartbeat, can_id: int, t: int, seq: int, add: _Add) -> None:
        """A driver's state change, and (with the session's config) the explanation of a latch, to /log/faults."""
        for lv, who, text in self._driver_change(hb):
            self._log(add, t, seq, lv, who, text)
        if self.latches is None:
            return
        n = hb.node_id
        w, dm = self._omega.get(n), self._delta.get(n)
        self.latches.feedback(n, self._theta.get(n), None if w is None else (w[0], w[1]),
                              None if dm is None else (dm[0], dm[1]))   # the newest feedback, read when it latches
        line = self.latches.on_heartbeat(hb)
        if line is not None:   # ERROR when it needs the user, WARNING when the edge clears it
            level = LogLevel.ERROR if latch_level(hb) >= logging.ERROR else LogLevel.WARNING
            self._log(add, t, seq, level, f"driver{n}", line)

    @staticmethod
    def _log(add: _Add, t_ns: int, seq: int, level: LogLevel, who: str, text: str) -> None:
        add(("/log/faults", t_ns, t_ns, message_bytes("/log/faults", log_message(t_ns, level, who, text)), seq))

    @property
    def restamps(self) -> bool:
        """Whether `stamp` changes a frame's time (a cia402 session on the sample time base)."""
        return self.canopen is not None and self.time_base != "wall"

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

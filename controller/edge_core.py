"""The edge's pure core (issue 28), beside `DriverCore` (plant_emulator/driver.py) and `ControllerCore`
(controller/remote_core.py): a CAN frame or a setpoint payload and the time in; the CAN frames to send, the Zenoh
payloads to publish and the counters out. No bus, no Zenoh session, no clock read of its own except the wall-clock
latency histograms (`wall_ns`). The edge node (controller/edge.py) and the per-bus `EdgeMux` (controller/edge_mux.py)
are its I/O shell: they receive, hand the core what arrived, meet the controller as their clock says (`sync`), and
send what the core returns (python-can's `BusABC` template method is the model: the shell fixed, the core inside).

Per feedback sample (one CAN FD frame, or three classic frames assembled, `on_frame`): `accept` it (its sample time
must advance), `publish` the state through the uplink link emulator (every outer sample; with the trigger at the
edge only on its events, `EdgeEvents`), take the setpoints the downlink emulator releases (`take_downlink`, after
`on_downlink` checked them: malformed, wrong type, an old or foreign session epoch, stale or duplicated seqs, outside
the setpoint envelope are counted and dropped; answers to states sampled more than `max_answer_age_s` before are
dropped as late), then `answer` with the VOLTAGE_CMD of the backstepping law on the held setpoint (or the tunnelled
voltage with `inner = "remote"`), and CLEAR_ERRORS when setpoints are fresh again after a watchdog fault (a
soft-limit fault is left to the operator). `stats` is the edge's `/stats` record, from the core's own counters.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import can

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_events import EdgeEvents
from sea_hil.controller.envelope import EnvelopeGate, SetpointEnvelope
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.drive_latches import LatchLog, latch_stats
from sea_hil.errors import MalformedFrame
from sea_hil.fault_explain import LatchWatch, latch_level
from sea_hil.protocol.can_assembly import FeedbackAssembler, unwrap_us
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import (
    LIMIT_FLAGS,
    ClearErrors,
    DriverState,
    ErrorFlags,
    Feedback,
    FeedbackAngle,
    FeedbackJoint1,
    FeedbackJoint2,
    Heartbeat,
    VoltageCmd,
)
from sea_hil.protocol.epoch import EpochVerdict, PeerEpoch, new_epoch
from sea_hil.protocol.keys import KEY_PAYLOADS
from sea_hil.protocol.link import DelayQueue, LinkEmulator
from sea_hil.protocol.payload_fields import RejectReason
from sea_hil.protocol.payload_hot import encode_event_state, encode_state
from sea_hil.protocol.payloads import (
    PAYLOAD_SIZE,
    MsgType,
    PayloadCounters,
    SetpointPayload,
    VoltagePayload,
)
from sea_hil.protocol.sequence import SequenceTracker, SeqVerdict
from sea_hil.protocol.wire_size import estimate_wire_bytes
from sea_hil.protocol.zsession import LinkedPublisher
from sea_hil.stats.histogram import LogHistogram

log = logging.getLogger("sea_hil.edge")
SETPOINT_BYTES = PAYLOAD_SIZE[MsgType.SETPOINT]
SAFE_STATES = (DriverState.FAULT, DriverState.ESTOP)
KEEP = 1000   # states remembered for latency bookkeeping


@dataclass
class EdgeCounters:
    feedback: int = 0
    rejected_frames: int = 0
    rejected_samples: int = 0            # feedback whose sample time does not advance (stale, clock reset)
    states_sent: int = 0
    state_bytes: int = 0
    setpoints: int = 0
    setpoint_bytes: int = 0
    voltages: int = 0
    stale_setpoints: int = 0
    unexpected_payloads: int = 0
    controller_restarts: int = 0
    bus_errors: int = 0
    clear_errors_sent: int = 0
    lockstep_resends: int = 0            # re-publishes after the controller first answered
    lockstep_startup_resends: int = 0    # re-publishes before its first ACK (controller starting)
    commands_sent: int = 0               # VOLTAGE_CMDs answering feedback samples
    arrival_commands: int = 0            # real time: extra VOLTAGE_CMDs sent when a setpoint arrived
    latency: LogHistogram = field(default_factory=LogHistogram)      # wall clock: state published -> answer arrived
    apply_latency: LogHistogram = field(default_factory=LogHistogram)  # wall clock: state published -> answer applied
    sim_latency: LogHistogram = field(default_factory=LogHistogram)  # sample time: state sampled -> applied
    loop: LogHistogram = field(default_factory=LogHistogram)         # feedback received -> VOLTAGE_CMD sent
    loop_overruns: int = 0                                           # loop time > one feedback period
    uplink_out_of_order: int = 0                                     # lockstep: released after a newer state
    resumes: int = 0                     # bumpless resumes after a stop / the drive's safe state (InnerLoop.resume)
    late_samples: int = 0                # real time: samples not answered, received > max_sample_age_s before
    late_setpoints: int = 0              # answers to states sampled > max_answer_age_s before: dropped


def percentiles_us(name: str, h: LogHistogram, keys: tuple[str, ...]) -> dict[str, float]:
    """`{name}_us_{key}` in microseconds (-1 when empty) for keys of `LogHistogram.to_dict` (min, p50, p99, max)."""
    d = h.to_dict()
    return {f"{name}_us_{k}": float(v) * 1e6 if (v := d[k]) is not None else -1.0 for k in keys}


class _Sink:
    """A `LinkedPublisher`'s putter that hands each released payload to the shell's `put`."""

    def __init__(self, put: Callable[[bytes], Any]) -> None:
        self.put = put


class StatePublisher:
    """One `StatePayload` per outer sample (the paper's placement) or one `EventStatePayload` per event of the edge's
    trigger (`publish_event`) through the uplink link emulator, with the wall time and sample time of each published
    state kept (for the closed-loop and simulated latencies). The header `t_ns` is the clock's stamp
    (`stamp(delivery_ns)`): the sender's monotonic clock in real time, the emulated link's delivery time on the
    simulated clock in lockstep (so the controller measures the uplink delay of every state: `sea_hil.runtime`)."""

    def __init__(self, uplink: LinkedPublisher, counters: EdgeCounters, epoch: int = 0,
                 stamp: Callable[[int], int] = lambda at_ns: time.monotonic_ns(),
                 wall_ns: Callable[[], int] = time.monotonic_ns) -> None:
        self.uplink = uplink
        self.epoch = epoch                      # this edge's session epoch (sea_hil.protocol.epoch)
        self.counters = counters
        self.stamp, self.wall_ns = stamp, wall_ns
        self.seq = 0
        self.sent_at: dict[int, int] = {}       # state seq -> wall time published
        self.sampled_at: dict[int, int] = {}    # state seq -> sample time

    def publish(self, fb: Feedback, sample_t_ns: int) -> tuple[int, bytes, int | None]:
        """Publish the state of `fb` (sampled at `sample_t_ns`); (seq, payload, delivery time or None if lost)."""
        self.seq += 1
        return self._put(self.seq, sample_t_ns, PAYLOAD_SIZE[MsgType.STATE],
                         lambda t: encode_state(self.seq, t, sample_t_ns, fb.theta_rad, fb.omega_rad_s, fb.delta_m,
                                                fb.nut_vel_m_s, epoch=self.epoch))

    def publish_event(self, fb: Feedback, sample_t_ns: int, seq: int, event_seq: int, reason: Any,
                      trajectory_id: int) -> tuple[int, bytes, int | None]:
        """Publish the event state `seq` (the sample index + 1) the edge's trigger chose."""
        self.seq = seq
        return self._put(seq, sample_t_ns, PAYLOAD_SIZE[MsgType.EVENT_STATE],
                         lambda t: encode_event_state(seq, t, sample_t_ns, fb.theta_rad, fb.omega_rad_s, fb.delta_m,
                                                      fb.nut_vel_m_s, event_seq, reason, trajectory_id,
                                                      epoch=self.epoch))

    def _put(self, seq: int, sample_t_ns: int, size: int, make: Callable[[int], bytes]
             ) -> tuple[int, bytes, int | None]:
        for book, value in ((self.sent_at, self.wall_ns()), (self.sampled_at, sample_t_ns)):
            book[seq] = value
            if len(book) > KEEP:
                del book[next(iter(book))]
        made: list[bytes] = []

        def data(at_ns: int) -> bytes:
            made.append(make(self.stamp(at_ns)))
            return made[0]
        at = self.uplink.put(data, sample_t_ns, wire_bytes=estimate_wire_bytes(size))
        if at is not None:      # None: lost on the emulated link, never awaited
            self.counters.states_sent += 1
            self.counters.state_bytes += size
        return seq, made[0] if made else b"", at

    def poll(self, now_ns: int) -> None:
        self.uplink.poll(now_ns)


class SetpointIntake:
    """Setpoint/voltage payloads from Zenoh are checked (malformed, wrong type, an old or foreign session epoch, stale
    or duplicated seqs are counted and dropped; a controller restart -- a new epoch -- is accepted when the clock
    allows it, `restart_possible(timed_out)`), pass the downlink link emulator, and are applied when it releases them
    (`take`), unless the state they answer was sampled more than `max_answer_age_ns` before (`late_setpoints`: a
    controller path starved or congested for longer would steer the limb on an old state; the setpoint timeout then
    makes the drive safe if no fresh answer comes)."""

    def __init__(self, downlink: LinkEmulator, counters: EdgeCounters, payloads: PayloadCounters, timeout_ns: int,
                 restart_possible: Callable[[bool], bool], envelope: EnvelopeGate | None = None,
                 max_answer_age_ns: int = 0, wall_ns: Callable[[], int] = time.monotonic_ns,
                 inner: str = "edge") -> None:
        self.downlink = downlink
        self.inner = inner                        # "edge": setpoints only; "remote": tunnelled voltages only
        self.channel = "setpoint" if inner == "edge" else "voltage"
        self.counters = counters
        self.payloads = payloads
        self.timeout_ns = timeout_ns
        self.restart_possible = restart_possible
        self.envelope = envelope                  # None: admit all
        self.max_answer_age_ns = max_answer_age_ns  # 0: off
        self.wall_ns = wall_ns
        self.sp_seq = SequenceTracker()
        self.epoch = PeerEpoch("controller", log)
        self.pending: DelayQueue[SetpointPayload | VoltagePayload] = DelayQueue()
        self.seen_setpoints: set[int] = set()
        self.last_rx_ns = 0                       # sample time of the newest accepted setpoint/voltage
        self.last_setpoint_ns: int | None = None  # sample time of the newest applied one
        self.on_refused: Callable[[int, int], None] | None = None   # (state seq, sample ns) of an envelope refusal

    def submit(self, data: bytes, sample_t_ns: int, sent_at: dict[int, int], rx_ns: int | None,
               channel: str | None = None) -> bool:
        """One payload from key `channel` ("setpoint" | "voltage"; None: the one of the inner loop's placement) at
        sample time `sample_t_ns`; True if it entered the downlink emulator. Closed-loop latency (`latency`) =
        arrival - publication of the state it answers, plus the delay the downlink emulator adds. A payload of
        another type than its key carries (`payload_rejected_key`), or on the key of the other inner placement (a
        voltage with the inner loop at the edge: `unexpected_payloads`), is rejected before the sequence check."""
        channel = channel or self.channel
        p = self.payloads.try_decode(data, KEY_PAYLOADS[channel])
        if p is None:
            return False
        assert isinstance(p, SetpointPayload | VoltagePayload)   # the only types of the two downlink keys
        if channel != self.channel:
            self.counters.unexpected_payloads += 1
            if self.counters.unexpected_payloads in (1, 10) or self.counters.unexpected_payloads % 1000 == 0:
                log.warning("%s payload dropped (%d so far): the inner loop runs %s, its key is %r", channel,
                            self.counters.unexpected_payloads, self.inner, self.channel)
            return False
        verdict = self.epoch.check(p.epoch, lambda: self._restart_allowed(p.seq, sample_t_ns))
        if verdict is EpochVerdict.REJECTED:
            return False
        if verdict is EpochVerdict.RESTART:
            self._controller_restarted(p.seq)
        elif self.sp_seq.feed(p.seq) is not SeqVerdict.NEW:
            self.counters.stale_setpoints += 1
            return False
        self.seen_setpoints.add(p.seq)
        self.last_rx_ns = sample_t_ns
        if isinstance(p, SetpointPayload) and self.envelope is not None \
                and not self.envelope.admit(p.seq, p.deflection_m):
            if self.on_refused is not None:   # an answer all the same: the edge trigger's anchor handshake counts it
                self.on_refused(p.state_seq, sample_t_ns)
            return False        # out of the envelope: seen (lockstep goes on), counted, never applied
        at = self.downlink.submit(sample_t_ns, len(data))
        if at is not None:
            self.pending.push(at, p)
            sent = sent_at.get(p.state_seq)
            if sent is not None and rx_ns is not None:
                self.counters.latency.record((max(rx_ns - sent, 0) + max(at - sample_t_ns, 0)) * 1e-9)
        return True

    def _restart_allowed(self, seq: int, sample_t_ns: int) -> bool:
        """A new controller epoch starts a new setpoint stream only after the old one timed out (the driver is then
        in its safe state) and only if it looks like a fresh sender (seq < the tracker window)."""
        timed_out = sample_t_ns - self.last_rx_ns > self.timeout_ns
        return self.restart_possible(timed_out) and seq < self.sp_seq.window

    def _controller_restarted(self, seq: int) -> None:
        self.sp_seq.restart()
        self.sp_seq.feed(seq)
        self.seen_setpoints.clear()
        self.counters.controller_restarts += 1
        log.warning("setpoint stream restarted at seq %d (controller restart)", seq)

    def fresh(self, now_ns: int) -> bool:
        return self.last_setpoint_ns is not None and now_ns - self.last_setpoint_ns <= self.timeout_ns

    def take(self, now_ns: int, sent_at: dict[int, int], sampled_at: dict[int, int],
             apply: Callable[[SetpointPayload | VoltagePayload], None]) -> bool:
        """Apply (`apply(payload)`) what the downlink emulator releases by sample time `now_ns`; True if any."""
        applied = False
        for p in self.pending.pop_due(now_ns):
            sampled = sampled_at.get(p.state_seq)
            if self._late(p, now_ns, sampled):
                continue
            applied = True
            sent = sent_at.get(p.state_seq)
            if sent is not None:
                self.counters.apply_latency.record(max(self.wall_ns() - sent, 1000) * 1e-9)
            if sampled is not None:
                self.counters.sim_latency.record((now_ns - sampled) * 1e-9)
            self.last_setpoint_ns = now_ns
            apply(p)
        return applied

    def _late(self, p: SetpointPayload | VoltagePayload, now_ns: int, sampled_ns: int | None) -> bool:
        """The answer to a state sampled more than `max_answer_age_ns` before `now_ns`: counted, logged, dropped."""
        if not self.max_answer_age_ns or sampled_ns is None or now_ns - sampled_ns <= self.max_answer_age_ns:
            return False
        self.counters.late_setpoints += 1
        n = self.counters.late_setpoints
        if n <= 10 or n % 100 == 0:
            log.warning("late setpoint %d dropped: it answers state seq %d sampled %.0f ms ago (max_answer_age_s "
                        "%.3f)", n, p.state_seq, (now_ns - sampled_ns) * 1e-6, self.max_answer_age_ns * 1e-9)
        return True


class EdgeClock(Protocol):
    """How the edge meets the controller (`sea_hil.runtime`: real time, lockstep): the clock strategy the core's
    `on_feedback` calls."""

    def repeat_feedback(self, fb: Feedback) -> bool: ...
    def state_sent(self, at_ns: int, seq: int, data: bytes) -> None: ...
    def sync(self, now_ns: int) -> None: ...
    def drain(self) -> bool: ...
    def gate(self, fresh: bool) -> tuple[bool, bool]: ...
    def late(self, rx_ns: int) -> bool: ...


class FreeRunning:
    """An `EdgeClock` that never waits: always commands and clears, answers every sample (the offline engine's and
    the core's tests' clock)."""

    def repeat_feedback(self, fb: Feedback) -> bool:
        return False

    def state_sent(self, at_ns: int, seq: int, data: bytes) -> None:
        pass

    def sync(self, now_ns: int) -> None:
        pass

    def drain(self) -> bool:
        return False

    def gate(self, fresh: bool) -> tuple[bool, bool]:
        return True, True

    def late(self, rx_ns: int) -> bool:
        return False


class CommandFrames(Protocol):
    """How the edge's answer goes on the bus (the extension point of the CAN side's profile): the frames commanding
    voltage `u` in answer to feedback `seq`, the frames resetting a (non-limit) drive fault, and whether a repeated
    sample may be answered by re-sending the last command (`repeatable`)."""

    repeatable: bool

    def command(self, u: tuple[float, float], seq: int) -> list[can.Message]: ...

    def clear(self) -> list[can.Message]: ...


class SeaCommands:
    """The sea profile's `CommandFrames`: one VOLTAGE_CMD (saturated to the DBC's range), CLEAR_ERRORS (protocol/sea.dbc)."""

    repeatable = True

    def __init__(self, codec: SeaCodec, node_id: int) -> None:
        self.codec, self.node_id = codec, node_id

    def command(self, u: tuple[float, float], seq: int) -> list[can.Message]:
        return [self.codec.encode(VoltageCmd(self.node_id, u, seq), saturate=True)]

    def clear(self) -> list[can.Message]:
        return [self.codec.encode(ClearErrors(self.node_id))]


class EdgeCore:
    """One limb's edge: see the module docstring. `state_sink(payload)` gets every state payload the uplink emulator
    releases (the shell puts it on Zenoh); `stamp(delivery_ns)` gives a state's header time and
    `restart_possible(timed_out)` says whether a new controller epoch may start a new setpoint stream (the clock's
    choices, `sea_hil.runtime`)."""

    def __init__(self, cfg: SeaHilConfig, node_id: int, *, inner: str = "edge", mode: str = "et",
                 state_sink: Callable[[bytes], Any] = lambda data: None,
                 record_sink: Callable[[dict[str, Any]], Any] = lambda record: None,
                 stamp: Callable[[int], int] = lambda at_ns: time.monotonic_ns(),
                 restart_possible: Callable[[bool], bool] = lambda timed_out: timed_out,
                 epoch: int | None = None, wall_ns: Callable[[], int] = time.monotonic_ns,
                 commands: CommandFrames | None = None) -> None:
        self.cfg, self.node_id, self.inner_mode = cfg, node_id, inner
        self.codec = SeaCodec.for_bus(cfg.can, [node_id])
        self.commands = commands if commands is not None else SeaCommands(self.codec, node_id)
        self.assembler = FeedbackAssembler()
        self.inner = InnerLoop(cfg, nominal_params(cfg), cfg.plant.initial_theta_rad,
                               1.0 / cfg.can.feedback_rate_hz)
        self.envelope = EnvelopeGate(SetpointEnvelope.from_config(cfg.safety.setpoint), log)
        self.period_ns = int(round(1e9 / cfg.can.feedback_rate_hz))
        self.max_sample_age_ns = int(round(cfg.safety.setpoint.max_sample_age_s * 1e9))
        self.outer_every = max(1, int(round(cfg.controller.sample_period_s * cfg.can.feedback_rate_hz)))
        self.counters = EdgeCounters()
        self.latches = LatchWatch(cfg.safety.drive if cfg.safety.drive.enabled else None,
                                  (cfg.plant.k1_n_per_m, cfg.plant.k2_n_per_m))   # a drive latch, explained once
        self.latch_log = LatchLog()               # every latch, counted in `stats` (the recording may have no CAN tap)
        self.payloads = PayloadCounters()
        seed = cfg.link.seed
        self.publisher = StatePublisher(LinkedPublisher(_Sink(state_sink), LinkEmulator(cfg.link.uplink, f"{seed}/up")),
                                        self.counters, new_epoch() if epoch is None else epoch, stamp, wall_ns)
        self.events = EdgeEvents(cfg, mode, self.inner, self.period_ns, self.outer_every) \
            if cfg.trigger.placement == "edge" else None
        self.intake = SetpointIntake(LinkEmulator(cfg.link.downlink, f"{seed}/down"), self.counters, self.payloads,
                                     int(round(2 * cfg.trigger.max_inter_event_s * 1e9)), restart_possible,
                                     self.envelope, int(round(cfg.safety.setpoint.max_answer_age_s * 1e9)), wall_ns,
                                     inner)
        if self.events is not None:
            self.intake.on_refused = self.events.heard
        self.voltage: tuple[float, float] | None = None    # the newest tunnelled voltage (inner = remote)
        self.driver_state = DriverState.INIT
        self.driver_flags = ErrorFlags(0)         # the driver's error flags from its latest HEARTBEAT
        self.last_cmd: can.Message | None = None
        self.record_sink = record_sink            # the edge trigger's tracking records (the shell publishes them)
        self.t_us_full = 0
        self.sample_t_ns = 0
        self.first_sample_t_ns = 0
        self.last_fb_seq: int | None = None
        self.last_fb: Feedback | None = None
        self.last_rx_ns = 0            # monotonic receive time of last_fb (0: unknown)
        self._stopped = False          # commanded once, then stopped (stale setpoints): resume bumplessly

    # ---- one feedback sample, in order --------------------------------------------------------------------------
    def on_feedback(self, fb: Feedback, rx_ns: int, clock: EdgeClock) -> list[can.Message] | None:
        """The whole sample: accept `fb` (received at monotonic `rx_ns`), publish its state, meet the controller
        (`clock.sync`: lockstep blocks there until the released states are answered), take what the downlink
        releases, answer. The frames to send (None: nothing, e.g. not commanding or a repeated sample the clock
        answered itself)."""
        if clock.repeat_feedback(fb) or not self.accept(fb, rx_ns):
            return None
        now = self.sample_t_ns
        for seq, data, at in self.publish(fb):
            clock.state_sent(at, seq, data)
        self.poll(now)
        clock.sync(now)
        clock.drain()
        self.take_downlink(now)
        return self.respond(fb, rx_ns, clock)

    def respond(self, fb: Feedback, rx_ns: int, clock: EdgeClock) -> list[can.Message] | None:
        """`answer` `fb` as the clock's gate and sample-age check say."""
        command, clear = clock.gate(self.fresh(self.sample_t_ns))
        return self.answer(fb, command, clear, command and clock.late(rx_ns))

    # ---- CAN in -------------------------------------------------------------------------------------------------
    def on_frame(self, msg: can.Message) -> Feedback | None:
        """One received CAN frame: the feedback sample it completes, else None (a heartbeat updates the drive's
        state; malformed frames are counted, `rejected_frames`, logged and ignored)."""
        try:
            frame = self.codec.decode(msg)
        except MalformedFrame as err:
            self.counters.rejected_frames += 1
            log.debug("ignored frame: %s", err)
            return None
        if isinstance(frame, Heartbeat):
            self.on_heartbeat(frame)
        elif isinstance(frame, Feedback):
            return frame
        elif isinstance(frame, FeedbackAngle | FeedbackJoint1 | FeedbackJoint2):   # the three classic parts
            return self.assembler.push(frame)
        return None

    def on_heartbeat(self, frame: Heartbeat) -> None:
        """The drive's state from its HEARTBEAT: explained once per latch (log line), counted per latch at the current
        sample time (`latch_log`, the `drive_latch*` fields of `stats`, sea_hil/drive_latches.py)."""
        self.driver_state, self.driver_flags = frame.state, frame.flags
        self.latch_log.on_heartbeat(self.sample_t_ns, frame)
        if (line := self.latches.on_heartbeat(frame, self.last_fb)) is not None:   # once per latch: the limit,
            log.log(latch_level(frame), "%s", line)         # the measured value, who clears it

    def accept(self, fb: Feedback, rx_ns: int) -> bool:
        """Take `fb` (received at monotonic `rx_ns`) as the current sample; False (counted) if its sample time does
        not advance."""
        c = self.counters
        t_us_full = unwrap_us(self.t_us_full, fb.t_us) if c.feedback else fb.t_us
        if c.feedback and t_us_full <= self.t_us_full:
            c.rejected_samples += 1
            log.debug("ignored feedback seq %d: sample time %d us not after %d us", fb.seq, t_us_full, self.t_us_full)
            return False
        self.last_fb_seq = fb.seq
        self.last_fb, self.last_rx_ns = fb, rx_ns
        if not c.feedback:
            self.first_sample_t_ns = t_us_full * 1000
        c.feedback += 1
        self.t_us_full = t_us_full
        self.sample_t_ns = t_us_full * 1000
        return True

    # ---- Zenoh out ----------------------------------------------------------------------------------------------
    def publish(self, fb: Feedback) -> list[tuple[int, bytes, int]]:
        """The states of the current sample entering the uplink emulator: (seq, payload, delivery time) each (lost
        ones not listed). Every outer sample, or with the trigger at the edge on its events (its tracking records
        go to `record_sink`, its local fallback into the inner loop)."""
        now = self.sample_t_ns
        if self.events is None:
            if round(now / self.period_ns) % self.outer_every:
                return []
            seq, data, at = self.publisher.publish(fb, now)
            return [] if at is None else [(seq, data, at)]
        d = self.events.on_sample(now, (fb.theta_rad, fb.omega_rad_s, fb.delta_m, fb.nut_vel_m_s))
        out: list[tuple[int, bytes, int]] = []
        if d is None:
            return out
        if d.reason is not None:
            seq, data, at = self.publisher.publish_event(fb, now, d.seq, d.event_seq, d.reason,
                                                         self.events.trajectory_id)
            if at is not None:
                out.append((seq, data, at))
        if d.hold is not None:          # the local fallback of a silent downlink (controller/edge_events.py)
            self.inner.hold(*d.hold)
        if d.record is not None:
            self.record_sink(d.record)
        return out

    def poll(self, now_ns: int) -> None:
        """Release what the uplink emulator holds by sample time `now_ns` (to `state_sink`)."""
        self.publisher.poll(now_ns)

    # ---- Zenoh in -----------------------------------------------------------------------------------------------
    def on_downlink(self, data: bytes, rx_ns: int | None = None, channel: str | None = None) -> bool:
        """One setpoint/voltage payload from Zenoh key `channel` (None: the inner placement's; `rx_ns`: monotonic
        arrival time); True if it entered the downlink emulator."""
        return self.intake.submit(data, self.sample_t_ns, self.publisher.sent_at, rx_ns, channel)

    def take_downlink(self, now_ns: int) -> bool:
        """Apply the setpoints/voltages the downlink emulator releases by sample time `now_ns`; True if any."""
        p = self.publisher
        return self.intake.take(now_ns, p.sent_at, p.sampled_at, self._apply)

    def _apply(self, p: SetpointPayload | VoltagePayload) -> None:
        if isinstance(p, SetpointPayload):
            self.inner.hold(p.deflection_m, p.sliding)
            self.counters.setpoints += 1
            self.counters.setpoint_bytes += SETPOINT_BYTES
        else:
            self.voltage = p.voltage_v
            self.counters.voltages += 1
        if self.events is not None:
            self.events.answered(p.state_seq, self.sample_t_ns)

    # ---- CAN out ------------------------------------------------------------------------------------------------
    def answer(self, fb: Feedback, command: bool, clear: bool, late: bool = False) -> list[can.Message] | None:
        """The frames answering `fb` (None: not commanding, or a sample too late to answer). `command`/`clear` come
        from the clock's gate on setpoint freshness (`fresh`), `late` from its sample-age check."""
        self._resume_if_stopped(fb, command, clear)
        if command and late:
            # a starved edge working through a backlog: this sample is too old to answer (its command would act
            # 10-20 ms late, an unstable inner loop); the inner loop still sees it, nothing is sent
            self.counters.late_samples += 1
            if self.inner_mode != "remote":
                self.inner.voltage((*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s))
            return None
        if not command:
            return None     # stop commanding: the driver watchdog takes it to its safe state
        frames = []
        if clear and self.driver_state is DriverState.FAULT and not self.driver_flags & LIMIT_FLAGS:
            frames.extend(self.commands.clear())
            self.counters.clear_errors_sent += 1
            self.driver_state = DriverState.INIT
            if self.events is not None and self.events.drive_cleared(self.sample_t_ns):
                log.info("drive cleared inside the lead-in at sample seq %d: re-anchoring the trajectory", fb.seq)
        if self.inner_mode == "remote":
            u = self.voltage if self.voltage is not None else (0.0, 0.0)
        else:
            u = self.inner.voltage((*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s))
        cmd = self.commands.command(u, fb.seq)
        self.last_cmd = cmd[-1] if self.commands.repeatable and cmd else None   # a repeated sample re-sends it
        frames.extend(cmd)
        return frames

    def fresh(self, now_ns: int) -> bool:
        """Has a setpoint been applied within the setpoint timeout?"""
        return self.intake.fresh(now_ns)

    def commanded(self, loop_ns: int) -> None:
        """The shell sent the command answering the current sample, `loop_ns` after its frame was received."""
        c = self.counters
        c.commands_sent += 1
        c.loop.record(max(loop_ns, 0) * 1e-9)
        c.loop_overruns += loop_ns > self.period_ns

    def _resume_if_stopped(self, fb: Feedback, command: bool, clear: bool) -> None:
        """Bumpless resume (`InnerLoop.resume`) when commanding starts again after a stop: the edge stopped commanding
        (stale setpoints) after it had commanded, or the drive is in its safe state (FAULT/ESTOP, as its heartbeat
        says) and may be cleared: after an edge restart, a controller restart or an outage. Never at a session's
        first command, never in lockstep (its gate always commands and never clears)."""
        if command and (self._stopped or (clear and self.driver_state in SAFE_STATES)):
            self.inner.resume(fb.delta_m)
            self.counters.resumes += 1
            if self.counters.resumes <= 10 or self.counters.resumes % 100 == 0:
                log.info("bumpless resume %d at sample seq %d (drive %s)", self.counters.resumes, fb.seq,
                         self.driver_state.name)
        self._stopped = not command and (self._stopped or self.counters.commands_sent > 0)

    def ran_elsewhere(self, accepted: int, commanded: int, saturated: int) -> None:
        """The offline session engine ran samples of this edge in its compiled kernel (sea_hil/offline/drive_kernel.py:
        this core's own inner step, between the samples it hands the core): `accepted` samples not passed to `accept`,
        `commanded` inner steps (VOLTAGE_CMDs), `saturated` of them clipped. Counted as the shell would count them,
        so `stats` is the session's; no loop time is recorded (none was measured)."""
        self.counters.feedback += accepted
        self.counters.commands_sent += commanded
        self.inner.saturated_steps += saturated

    # ---- counters out -------------------------------------------------------------------------------------------
    def stats(self) -> dict[str, float]:
        """The edge's flat counters (the fields of its stats record; keys read by the session summary)."""
        c, intake, pub = self.counters, self.intake, self.publisher
        lat = c.latency.to_dict()
        up, down = pub.uplink.link.counters(), intake.downlink.counters()
        sp_seq = intake.sp_seq
        out: dict[str, Any] = {     # counts and floats (the epoch's and the latency's dicts are typed loosely)
            "node_id": self.node_id, "feedback_samples": c.feedback, "rejected_frames": c.rejected_frames,
            "rejected_samples": c.rejected_samples,
            "uplink_msgs": c.states_sent, "uplink_bytes": c.state_bytes, "downlink_applied": c.setpoints,
            "voltage_msgs_applied": c.voltages, "stale_setpoints": c.stale_setpoints,
            "clear_errors_sent": c.clear_errors_sent, "lockstep_resends": c.lockstep_resends,
            "lockstep_startup_resends": c.lockstep_startup_resends,
            "commands_sent": c.commands_sent, "arrival_commands": c.arrival_commands,
            "payload_rejected": self.payloads.as_dict()["rejected_total"],
            **{f"payload_rejected_{r.value}": self.payloads.rejected[r.value] for r in RejectReason},
            "unexpected_payloads": c.unexpected_payloads, "controller_restarts": c.controller_restarts,
            "setpoints_out_of_envelope": self.envelope.rejected,
            "bus_errors": c.bus_errors, "late_samples": c.late_samples, "late_setpoints": c.late_setpoints,
            "uplink_dropped": up.dropped, "downlink_dropped": down.dropped,
            "saturated_steps": self.inner.saturated_steps,
            "seq_lost": sp_seq.lost, "seq_reordered": sp_seq.reordered, "seq_duplicates": sp_seq.duplicates,
            **intake.epoch.as_dict(),
            "latency_count": lat["count"],
            "uplink_submitted": up.submitted, "uplink_mean_added_delay_s": up.mean_added_delay_s,
            "downlink_submitted": down.submitted, "downlink_mean_added_delay_s": down.mean_added_delay_s,
        }
        for k in ("p50", "p90", "p99", "max", "min", "mean"):
            v = lat.get(k)
            out[f"latency_{k}_us"] = (v * 1e6) if v is not None else -1.0
        out.update(percentiles_us("sim_latency", c.sim_latency, ("min", "p50", "max")),
                   **percentiles_us("apply_latency", c.apply_latency, ("p50", "p99", "max")),
                   **percentiles_us("loop", c.loop, ("p50", "p99", "max")),
                   loop_count=c.loop.count, loop_overruns=c.loop_overruns, uplink_out_of_order=c.uplink_out_of_order,
                   uplink_pending=pub.uplink.pending, **latch_stats(self.latch_log.latches, self.first_sample_t_ns,
                                                                  self.node_id))
        if self.events is not None:     # the trigger at the edge (issue 16); absent on the paper's path
            out.update(self.events.stats(), **self.events.fallback_stats())
        return out

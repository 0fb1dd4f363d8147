"""The edge node: CAN <-> Zenoh bridge next to the driver, running the backstepping inner loop at the driver's
feedback rate with the latest setpoint v_x(t_i) held.

Per feedback sample (one CAN FD frame, or three classic frames assembled): publish the state to Zenoh every outer sample (`StatePublisher`,
uplink link emulator), meet the controller as the clock says (`sync`), take setpoints that have arrived
(`SetpointIntake`, downlink link emulator), compute the voltage and send VOLTAGE_CMD (`CommandPath`). With
`inner="remote"` the voltages come from the controller over Zenoh and are tunnelled to CAN as received (held).
Link emulation runs here for both directions, clocked by the driver's sample time (1 ms resolution), so lockstep
runs are deterministic (`sea_hil.runtime.lockstep`: an answer to state k takes effect no earlier than k's sample
time + uplink + downlink delay, in simulated time, `sim_latency_us_*`, at no cost in wall time).

Real-time clock: if no setpoint arrives for `setpoint_timeout_s` the edge stops commanding, so the driver's watchdog
puts it into its safe state; when setpoints come back the edge clears the fault. A setpoint (or tunnelled voltage)
the downlink emulator releases at once is applied on arrival: the Zenoh callback recomputes the voltage from the
newest feedback and sends an extra VOLTAGE_CMD (`arrival_commands`), instead of waiting up to a period for the next
sample; a lock serialises it with the feedback path. Per answered sample the loop time (frame received ->
VOLTAGE_CMD sent) is kept in a histogram (`loop_us_*`, `loop_overruns` = longer than one period).
"""
from __future__ import annotations

import json
import logging
import threading
import time

import can
import zenoh

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_command import CommandPath
from sea_hil.controller.edge_downlink import SetpointIntake
from sea_hil.controller.edge_events import EdgeEvents
from sea_hil.controller.edge_stats import EdgeCounters, edge_stats, receive_stamped
from sea_hil.controller.edge_uplink import StatePublisher
from sea_hil.controller.envelope import EnvelopeGate, SetpointEnvelope
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.errors import ConfigError, MalformedFrame
from sea_hil.fault_explain import LatchWatch, latch_level
from sea_hil.protocol.can_assembly import FeedbackAssembler, unwrap_us
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import (
    DriverState,
    Feedback,
    FeedbackAngle,
    FeedbackJoint1,
    FeedbackJoint2,
    Heartbeat,
)
from sea_hil.protocol.canbus import CanHandle
from sea_hil.protocol.epoch import new_epoch
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import LinkEmulator
from sea_hil.protocol.payloads import PayloadCounters
from sea_hil.protocol.zsession import LinkedPublisher, publisher
from sea_hil.runtime.clock import Clock, EdgeSync, RealTimeClock
from sea_hil.runtime.node import Node

log = logging.getLogger("sea_hil.edge")
SAFE_STATES = (DriverState.FAULT, DriverState.ESTOP)


class EdgeNode(Node):
    kind = "edge"

    def __init__(self, cfg: SeaHilConfig, bus: CanHandle, session: zenoh.Session, node_id: int, *,
                 inner: str = "edge", clock: Clock | None = None, mode: str = "et") -> None:
        if inner not in ("edge", "remote"):
            raise ValueError("inner must be 'edge' or 'remote'")
        if cfg.trigger.placement == "edge" and (inner != "edge" or mode not in ("et", "tt")):
            raise ConfigError("trigger.placement = 'edge' needs the inner loop at the edge and --controller et|tt")
        super().__init__()
        self.cfg, self.bus, self.node_id = cfg, bus, node_id
        self.codec = SeaCodec.for_bus(cfg.can, [node_id])
        self.assembler = FeedbackAssembler()
        self.keys = Keys.from_config(cfg.zenoh)
        self.inner = InnerLoop(cfg, nominal_params(cfg), cfg.plant.initial_theta_rad,
                               1.0 / cfg.can.feedback_rate_hz)
        self.envelope = EnvelopeGate(SetpointEnvelope.from_config(cfg.safety.setpoint), log)
        self.period_ns = int(round(1e9 / cfg.can.feedback_rate_hz))
        self.max_sample_age_ns = int(round(cfg.safety.setpoint.max_sample_age_s * 1e9))
        self.outer_every = max(1, int(round(cfg.controller.sample_period_s * cfg.can.feedback_rate_hz)))
        self.counters = EdgeCounters()
        self.latches = LatchWatch(cfg.safety.drive if cfg.safety.drive.enabled else None,
                                  (cfg.plant.k1_n_per_m, cfg.plant.k2_n_per_m))   # a drive latch, explained once
        self.payloads = PayloadCounters()
        self.lock = threading.Lock()       # feedback path vs. setpoint arrival (Zenoh callback thread)
        self.sync: EdgeSync = (clock or RealTimeClock()).edge(self)
        seed = cfg.link.seed
        self.publisher = StatePublisher(
            LinkedPublisher(publisher(session, self.keys.state, congestion_control=self.sync.congestion_control),
                            LinkEmulator(cfg.link.uplink, f"{seed}/up")),
            self.counters, new_epoch(), self.sync.state_stamp)
        self.events = EdgeEvents(cfg, mode, self.inner, self.period_ns, self.outer_every) \
            if cfg.trigger.placement == "edge" else None
        self.event_pub = publisher(session, self.keys.event, express=False,
                                   congestion_control=zenoh.CongestionControl.BLOCK) if self.events else None
        self.intake = SetpointIntake(LinkEmulator(cfg.link.downlink, f"{seed}/down"), self.counters, self.payloads,
                                     int(round(2 * cfg.trigger.max_inter_event_s * 1e9)), self.sync,
                                     self.envelope, int(round(cfg.safety.setpoint.max_answer_age_s * 1e9)),
                                     inner=inner)
        self.command_path = CommandPath(bus, self.codec, node_id, self.inner, inner, cfg.can.send_retries,
                                        self.counters)
        self.stats_pub = publisher(session, self.keys.stats, express=False)
        self.t_us_full = 0
        self.sample_t_ns = 0
        self.last_fb_seq: int | None = None
        self.last_fb: Feedback | None = None
        self.last_rx_ns = 0            # monotonic receive time of last_fb (0: unknown)
        self._stopped = False          # commanded once, then stopped (stale setpoints): resume bumplessly
        self._subs = [session.declare_subscriber(self.keys.setpoint, self.sync.downlink_callback("setpoint")),
                      session.declare_subscriber(self.keys.voltage, self.sync.downlink_callback("voltage")),
                      session.declare_subscriber(self.keys.control, self.sync.control_callback())]

    # ---- the node hooks -------------------------------------------------------------------------------------------
    def _step(self) -> bool:
        got = receive_stamped(self.bus, self.stop_event, self._bus_error)
        if got is None:
            return False
        self.on_can(*got)
        return True

    def _bus_error(self, err: Exception) -> None:
        self.counters.bus_errors += 1
        log.warning("CAN receive failed: %s", err)

    def _close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        if self.event_pub is not None:
            self.event_pub.undeclare()

    def _stats(self) -> dict[str, float]:
        return edge_stats(self)

    # ---- CAN side -------------------------------------------------------------------------------------------------
    def on_can(self, msg: can.Message, now_ns: int) -> None:
        """Handle one received CAN frame (`now_ns`: its monotonic receive time, the start of the loop time of the
        sample it completes). Malformed frames are counted (`rejected_frames`), logged and ignored."""
        try:
            frame = self.codec.decode(msg)
        except MalformedFrame as err:
            self.counters.rejected_frames += 1
            log.debug("ignored frame: %s", err)
            return
        if isinstance(frame, Heartbeat):
            self.command_path.driver_state, self.command_path.driver_flags = frame.state, frame.flags
            if (line := self.latches.on_heartbeat(frame, self.last_fb)) is not None:   # once per latch: the limit,
                log.log(latch_level(frame), "%s", line)         # the measured value, who clears it
        elif isinstance(frame, Feedback | FeedbackAngle | FeedbackJoint1 | FeedbackJoint2):   # FD, or 3 classic
            fb = frame if isinstance(frame, Feedback) else self.assembler.push(frame)
            if fb is not None:
                with self.lock:
                    self._on_feedback(fb, now_ns)

    def _on_feedback(self, fb: Feedback, rx_ns: int) -> None:
        if self.sync.repeat_feedback(fb):
            return
        c = self.counters
        t_us_full = unwrap_us(self.t_us_full, fb.t_us) if c.feedback else fb.t_us
        if c.feedback and t_us_full <= self.t_us_full:   # sample time must advance
            c.rejected_samples += 1
            log.debug("ignored feedback seq %d: sample time %d us not after %d us", fb.seq, t_us_full,
                      self.t_us_full)
            return
        self.last_fb_seq = fb.seq
        self.last_fb, self.last_rx_ns = fb, rx_ns
        c.feedback += 1
        self.t_us_full = t_us_full
        now = self.sample_t_ns = self.t_us_full * 1000
        if self.events is not None:
            self._edge_trigger(fb, now)
        elif round(now / self.period_ns) % self.outer_every == 0:
            seq, data, at = self.publisher.publish(fb, now)
            if at is not None:
                self.sync.state_sent(at, seq, data)
        self.publisher.poll(now)
        self.sync.sync(now)
        self.take_downlink(now)
        if not self._answer(fb, now, rx_ns):
            return
        c.commands_sent += 1
        loop_ns = time.monotonic_ns() - rx_ns
        c.loop.record(max(loop_ns, 0) * 1e-9)
        c.loop_overruns += loop_ns > self.period_ns

    def _edge_trigger(self, fb: Feedback, now: int) -> None:
        """The trigger at the edge: publish this sample only on an event; the tracking record of an outer sample."""
        d = self.events.on_sample(now, (fb.theta_rad, fb.omega_rad_s, fb.delta_m, fb.nut_vel_m_s))  # type: ignore
        if d is None:
            return
        if d.reason is not None:
            seq, data, at = self.publisher.publish_event(fb, now, d.seq, d.event_seq, d.reason,
                                                         self.events.trajectory_id)  # type: ignore[union-attr]
            if at is not None:
                self.sync.state_sent(at, seq, data)
        if d.hold is not None:          # the local fallback of a silent downlink (controller/edge_events.py)
            self.inner.hold(*d.hold)
        if d.record is not None:
            self.event_pub.put(json.dumps(d.record).encode())  # type: ignore[union-attr]

    def _apply(self, p: object) -> None:
        self.command_path.apply(p)
        if self.events is not None:
            self.events.answered(p.state_seq, self.sample_t_ns)  # type: ignore[attr-defined]

    def _answer(self, fb: Feedback, now: int, rx_ns: int) -> bool:
        command, clear = self.sync.gate(self.intake.fresh(now))
        self._resume_if_stopped(fb, command, clear)
        if command and self.sync.late(rx_ns):
            # a starved edge working through a backlog: this sample is too old to answer (its command would act
            # 10-20 ms late, an unstable inner loop); the inner loop still sees it, nothing is sent
            self.counters.late_samples += 1
            self.command_path.step_only(fb)
            return False
        cleared = self.counters.clear_errors_sent
        sent = self.command_path.answer(fb, command, clear)
        if self.events is not None and self.counters.clear_errors_sent != cleared and self.events.drive_cleared(now):
            log.info("drive cleared inside the lead-in at sample seq %d: re-anchoring the trajectory", fb.seq)
        return sent

    # ---- restart path ---------------------------------------------------------------------------------------------
    def _resume_if_stopped(self, fb: Feedback, command: bool, clear: bool) -> None:
        """Bumpless resume (`InnerLoop.resume`) when commanding starts again after a stop: the edge stopped commanding
        (stale setpoints) after it had commanded, or the drive is in its safe state (FAULT/ESTOP, as its heartbeat
        says) and may be cleared: after an edge restart, a controller restart or an outage. Never at a session's
        first command, never in lockstep (its gate always commands and never clears)."""
        if command and (self._stopped or (clear and self.command_path.driver_state in SAFE_STATES)):
            self.inner.resume(fb.delta_m)
            self.counters.resumes += 1
            if self.counters.resumes <= 10 or self.counters.resumes % 100 == 0:
                log.info("bumpless resume %d at sample seq %d (drive %s)", self.counters.resumes, fb.seq,
                         self.command_path.driver_state.name)
        self._stopped = not command and (self._stopped or self.counters.commands_sent > 0)

    # ---- Zenoh side -----------------------------------------------------------------------------------------------
    def on_arrival(self, data: bytes, rx_ns: int, channel: str | None = None) -> None:
        """Real time: handle a setpoint/voltage payload from key `channel` when it arrives (`on_downlink`) and, if the
        downlink emulator releases it at once, apply it and send the voltage it gives with the newest feedback."""
        with self.lock:
            if self.stop_event.is_set() or not self.on_downlink(data, rx_ns, channel) or self.last_fb is None:
                return
            now = self.sample_t_ns
            if self.take_downlink(now) and self._answer(self.last_fb, now, self.last_rx_ns):
                self.counters.arrival_commands += 1

    def on_downlink(self, data: bytes, rx_ns: int | None = None, channel: str | None = None) -> bool:
        """Handle one setpoint/voltage payload from Zenoh key `channel` (None: the inner placement's; `rx_ns`:
        monotonic arrival time); True if it entered the downlink emulator (`SetpointIntake.submit`)."""
        return self.intake.submit(data, self.sample_t_ns, self.publisher.sent_at, rx_ns, channel)

    def on_ack(self, data: bytes) -> bool:
        """Handle one payload from the control key (lockstep ACKs; counted and dropped otherwise)."""
        return bool(self.sync.on_ack(data))

    def take_downlink(self, now: int) -> bool:
        """Apply the setpoints/voltages the downlink emulator releases by sample time `now`; True if any."""
        self.sync.drain()
        p = self.publisher
        return self.intake.take(now, p.sent_at, p.sampled_at, self._apply)

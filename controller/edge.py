"""The edge node: CAN <-> Zenoh bridge next to the driver, running the backstepping inner loop at the driver's
feedback rate with the latest setpoint v_x(t_i) held.

Per feedback sample (three CAN frames assembled): publish the state to Zenoh every outer sample (uplink link
emulator), take setpoints that have arrived (downlink link emulator), compute the voltage and send VOLTAGE_CMD.
With `inner="remote"` the voltages come from the controller over Zenoh and are tunnelled to CAN as received (held).
Link emulation runs here for both directions, clocked by the driver's sample time (1 ms resolution), so lockstep
runs are deterministic. In lockstep the edge waits for the controller's answer to a state from the sample at which
the uplink emulator releases it (the plant steps on while it is in flight, as in real time), and a setpoint enters
the downlink emulator at that sample: an answer to state k takes effect no earlier than k's sample time + uplink +
downlink delay, in simulated time (`sim_latency_us_*`), at no cost in wall time. If no setpoint arrives for
`setpoint_timeout_s` the edge stops commanding, so the driver's watchdog puts it into its safe state; when setpoints
come back the edge clears the fault. In real time a setpoint (or tunnelled voltage) the downlink emulator releases at
once is applied on arrival: the Zenoh callback recomputes the voltage from the newest feedback and sends an extra
VOLTAGE_CMD (`arrival_commands`), instead of waiting up to a period for the next sample; a lock serialises it with
the feedback path. The lockstep waits and the callback-fed inbox are in `controller/edge_lockstep.py`. `on_can`
handles one received frame; per answered sample the loop time (frame received -> VOLTAGE_CMD sent) is kept in a
histogram (`loop_us_*`, `loop_overruns` = longer than one period).
"""
from __future__ import annotations

import json
import logging
import queue
import threading
import time

import can
import zenoh

from sea_hil.controller.edge_lockstep import LockstepPlane
from sea_hil.controller.envelope import EnvelopeGate, SetpointEnvelope
from sea_hil.controller.edge_stats import EdgeCounters, percentiles_us, rx_monotonic_ns
from sea_hil.controller.inner import InnerLoop
from sea_hil.protocol.can_codec import (ClearErrors, DriverState, Feedback, FeedbackAssembler, Heartbeat, SeaCodec,
                                VoltageCmd, unwrap_us, FEEDBACK_PARTS)
from sea_hil.protocol.can_frames import LIMIT_FLAGS, ErrorFlags
from sea_hil.protocol.canbus import send_with_retry
from sea_hil.config import SeaHilConfig
from sea_hil.errors import BusError, MalformedFrame
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import DelayQueue, LinkEmulator
from sea_hil.mechanics import limb_params
from sea_hil.protocol.payloads import (AckPayload, PayloadCounters, SequenceTracker, SeqVerdict, SetpointPayload,
                               StatePayload, VoltagePayload, encode)
from sea_hil.protocol.zsession import LinkedPublisher, publisher

log = logging.getLogger("sea_hil.edge")


class EdgeNode(LockstepPlane):
    def __init__(self, cfg: SeaHilConfig, bus: can.BusABC, session: zenoh.Session, node_id: int, *,
                 inner: str = "edge", lockstep: bool = False, resend_s: float = 0.1) -> None:
        if inner not in ("edge", "remote"):
            raise ValueError("inner must be 'edge' or 'remote'")
        self.cfg, self.bus, self.node_id, self.inner_mode, self.lockstep = cfg, bus, node_id, inner, lockstep
        self.codec = SeaCodec([node_id])
        self.assembler = FeedbackAssembler()
        self.keys = Keys.from_config(cfg.zenoh)
        p = limb_params(cfg.plant)
        self.inner = InnerLoop(cfg, p, tuple(cfg.plant.initial_theta_rad))
        self.envelope = EnvelopeGate(SetpointEnvelope.from_config(cfg.safety.setpoint), log)
        self.period_ns = int(round(1e9 / cfg.can.feedback_rate_hz))
        self.outer_every = max(1, int(round(cfg.zenoh.state_period_s * cfg.can.feedback_rate_hz)))
        self.timeout_ns = int(round(2 * cfg.trigger.max_inter_event_s * 1e9))
        self.resend_ns = int(resend_s * 1e9)
        seed = cfg.link.seed
        self.uplink = LinkedPublisher(publisher(session, self.keys.state), LinkEmulator(cfg.link.uplink, f"{seed}/up"))
        self.downlink = LinkEmulator(cfg.link.downlink, f"{seed}/down")
        self.pending_down: DelayQueue[object] = DelayQueue()
        self.stats_pub = publisher(session, self.keys.stats, express=False)
        # one FIFO fed by callbacks (is_ack, payload): lockstep waits block on it instead of polling
        self._inbox: queue.SimpleQueue[tuple[bool, bytes, int]] = queue.SimpleQueue()
        downlink_cb = self._to_inbox(False) if lockstep else self._on_arrival_sample
        self.sp_sub = session.declare_subscriber(self.keys.setpoint, downlink_cb)
        self.v_sub = session.declare_subscriber(self.keys.voltage, downlink_cb)
        self.ack_sub = session.declare_subscriber(self.keys.control, self._to_inbox(True))
        self.payloads = PayloadCounters()
        self.sp_seq = SequenceTracker()
        self.counters = EdgeCounters()
        self.stop_event = threading.Event()
        self._t_us_full = 0
        self._sample_t_ns = 0
        self._state_seq = 0
        self._sent_at: dict[int, int] = {}           # state seq -> wall time published
        self._sampled_at: dict[int, int] = {}        # state seq -> sample time
        self._in_flight: DelayQueue[tuple[int, bytes]] = DelayQueue()   # lockstep: states held by the uplink link
        self._newest_released = 0
        self._last_setpoint_ns: int | None = None
        self._last_rx_ns = 0          # sample time of the newest accepted setpoint/voltage
        self._voltage: tuple[float, float] | None = None
        self._driver_state = DriverState.INIT
        self._driver_flags = ErrorFlags(0)
        self._last_fb_seq: int | None = None
        self._last_cmd: can.Message | None = None
        self._acks: dict[int, AckPayload] = {}
        self._awaiting: dict[int, bytes] = {}
        self._seen_setpoints: set[int] = set()
        self._lock = threading.Lock()       # feedback path vs. setpoint arrival (Zenoh callback thread)
        self._last_fb: Feedback | None = None

    # ---- CAN side -----------------------------------------------------------------------------------------------
    def run(self) -> None:
        while not self.stop_event.is_set():
            try:
                msg = self.bus.recv(timeout=0.05)
            except (can.CanError, OSError) as err:   # e.g. interface down: count, log, keep running
                self.counters.bus_errors += 1
                log.warning("CAN receive failed: %s", err)
                self.stop_event.wait(0.05)
                continue
            if msg is not None:
                self.on_can(msg, rx_monotonic_ns(msg.timestamp, time.monotonic_ns(), time.time_ns()))

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
            self._driver_state, self._driver_flags = frame.state, frame.flags
        elif isinstance(frame, FEEDBACK_PARTS):
            fb = self.assembler.push(frame)
            if fb is not None:
                self._on_feedback(fb, now_ns)

    def _send(self, msg: can.Message) -> None:
        try:
            send_with_retry(self.bus, msg, self.cfg.can.send_retries, 0.0002)
        except BusError as err:
            self.counters.bus_errors += 1
            log.warning("%s", err)

    def _on_feedback(self, fb: Feedback, rx_ns: int) -> None:
        with self._lock:
            self._on_feedback_locked(fb, rx_ns)

    def _on_feedback_locked(self, fb: Feedback, rx_ns: int) -> None:
        if self.lockstep and fb.seq == self._last_fb_seq and self._last_cmd is not None:
            self._send(self._last_cmd)      # the driver re-sent a sample we already answered
            return
        t_us_full = unwrap_us(self._t_us_full, fb.t_us) if self.counters.feedback else fb.t_us
        if self.counters.feedback and t_us_full <= self._t_us_full:   # sample time must advance
            self.counters.rejected_samples += 1
            log.debug("ignored feedback seq %d: sample time %d us not after %d us", fb.seq, t_us_full,
                      self._t_us_full)
            return
        self._last_fb_seq = fb.seq
        self._last_fb = fb
        self.counters.feedback += 1
        self._t_us_full = t_us_full
        now = self._sample_t_ns = self._t_us_full * 1000
        k = round(now / self.period_ns)
        if k % self.outer_every == 0:
            self._publish_state(fb, now)
        self.uplink.poll(now)
        if self.lockstep:
            self._await_released(now)
            self._wait_for_controller()
        self._take_downlink(now)
        if not self._send_command(fb, now):
            return
        self.counters.commands_sent += 1
        loop_ns = time.monotonic_ns() - rx_ns
        self.counters.loop.record(max(loop_ns, 0) * 1e-9)
        self.counters.loop_overruns += loop_ns > self.period_ns

    def _send_command(self, fb: Feedback, now: int) -> bool:
        """Compute and send the VOLTAGE_CMD answering feedback `fb` (False: not commanding)."""
        u = self._command(fb, now)
        if u is None:
            return False
        self._last_cmd = self.codec.encode(VoltageCmd(self.node_id, u, fb.seq), saturate=True)
        self._send(self._last_cmd)
        return True

    def _command(self, fb: Feedback, now: int) -> tuple[float, float] | None:
        fresh = self._last_setpoint_ns is not None and now - self._last_setpoint_ns <= self.timeout_ns
        if not fresh and not self.lockstep:
            return None     # stop commanding: the driver watchdog takes it to its safe state
        # a watchdog fault is cleared when setpoints come back, a soft-limit fault (LIMIT_FLAGS) is left to the operator
        if fresh and self._driver_state is DriverState.FAULT and not self._driver_flags & LIMIT_FLAGS \
                and not self.lockstep:
            self._send(self.codec.encode(ClearErrors(self.node_id)))
            self.counters.clear_errors_sent += 1
            self._driver_state = DriverState.INIT
        if self.inner_mode == "remote":
            return self._voltage if self._voltage is not None else (0.0, 0.0)
        m = (*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s)
        return self.inner.voltage(m)  # type: ignore[arg-type]

    # ---- Zenoh side ---------------------------------------------------------------------------------------------
    def _publish_state(self, fb: Feedback, sample_t_ns: int) -> None:
        self._state_seq += 1
        t = time.monotonic_ns()
        data = encode(StatePayload(self._state_seq, t, sample_t_ns, fb.theta_rad, fb.omega_rad_s, fb.delta_m,
                                   fb.nut_vel_m_s))
        self._sent_at[self._state_seq] = t
        self._sent_at.pop(self._state_seq - 1000, None)
        self._sampled_at[self._state_seq] = sample_t_ns
        self._sampled_at.pop(self._state_seq - 1000, None)
        at = self.uplink.put(data, sample_t_ns)
        if at is not None:      # None: lost on the emulated link, never awaited
            self.counters.states_sent += 1
            self.counters.state_bytes += len(data)
            if self.lockstep:
                self._in_flight.push(at, (self._state_seq, data))

    def _on_arrival_sample(self, sample: zenoh.Sample) -> None:
        self.on_arrival(sample.payload.to_bytes(), time.monotonic_ns())

    def on_arrival(self, data: bytes, rx_ns: int) -> None:
        """Real time: handle a setpoint/voltage payload when it arrives (`on_downlink`) and, if the downlink emulator
        releases it at once, apply it and send the voltage it gives with the newest feedback."""
        with self._lock:
            if self.stop_event.is_set() or not self.on_downlink(data, rx_ns) or self._last_fb is None:
                return
            if self._take_downlink(self._sample_t_ns) and self._send_command(self._last_fb, self._sample_t_ns):
                self.counters.arrival_commands += 1

    def on_downlink(self, data: bytes, rx_ns: int | None = None) -> bool:
        """Handle one setpoint/voltage payload from Zenoh (`rx_ns`: monotonic arrival time): malformed (counted by
        reason) or wrong-type payloads and stale/duplicated seqs (`stale_setpoints`) are dropped; True if it entered
        the downlink emulator. Closed-loop latency (`latency`) = arrival - publication of the state it answers, plus
        the delay the downlink emulator adds."""
        p = self.payloads.try_decode(data)
        if p is None:
            return False
        if not isinstance(p, (SetpointPayload, VoltagePayload)):
            self.counters.unexpected_payloads += 1
            return False
        if self.sp_seq.feed(p.seq) is not SeqVerdict.NEW:
            if not self._controller_restarted(p.seq):
                self.counters.stale_setpoints += 1
                return False
        self._seen_setpoints.add(p.seq)
        self._last_rx_ns = self._sample_t_ns
        if isinstance(p, SetpointPayload) and not self.envelope.admit(p.seq, p.deflection_m):
            return False        # out of the envelope: seen (lockstep goes on), counted, never applied
        at = self.downlink.submit(self._sample_t_ns, len(data))
        if at is not None:
            self.pending_down.push(at, p)
            sent = self._sent_at.get(p.state_seq)
            if sent is not None and rx_ns is not None:
                self.counters.latency.record((max(rx_ns - sent, 0) + max(at - self._sample_t_ns, 0)) * 1e-9)
        return True

    def _controller_restarted(self, seq: int) -> bool:
        """A not-newer seq starts a new setpoint stream only after the old one timed out (the driver is then in its
        safe state) and only if it looks like a fresh sender (seq < the tracker window); counted."""
        timed_out = self._sample_t_ns - self._last_rx_ns > self.timeout_ns
        if self.lockstep or not timed_out or seq >= self.sp_seq.window:
            return False
        self.sp_seq.restart()
        self.sp_seq.feed(seq)
        self._seen_setpoints.clear()
        self.counters.controller_restarts += 1
        log.warning("setpoint stream restarted at seq %d (controller restart)", seq)
        return True

    def _take_downlink(self, now: int) -> bool:
        """Apply the setpoints/voltages the downlink emulator releases by sample time `now`; True if any."""
        self._drain_zenoh()
        applied = False
        for p in self.pending_down.pop_due(now):
            applied = True
            t = time.monotonic_ns()
            sent = self._sent_at.get(p.state_seq)   # type: ignore[attr-defined]
            if sent is not None:
                self.counters.apply_latency.record(max(t - sent, 1000) * 1e-9)
            sampled = self._sampled_at.get(p.state_seq)   # type: ignore[attr-defined]
            if sampled is not None:
                self.counters.sim_latency.record((now - sampled) * 1e-9)
            self._last_setpoint_ns = now
            if isinstance(p, SetpointPayload):
                self.inner.hold(p.deflection_m, p.sliding)
                self.counters.setpoints += 1
                self.counters.setpoint_bytes += 53
            else:
                self._voltage = p.voltage_v
                self.counters.voltages += 1
        return applied

    # ---- stats --------------------------------------------------------------------------------------------------
    def stats_dict(self) -> dict[str, float]:
        c = self.counters
        lat = c.latency.to_dict()
        up, down = self.uplink.link.counters(), self.downlink.counters()
        out: dict[str, float] = {
            "node_id": self.node_id, "feedback_samples": c.feedback, "rejected_frames": c.rejected_frames,
            "rejected_samples": c.rejected_samples,
            "uplink_msgs": c.states_sent, "uplink_bytes": c.state_bytes, "downlink_applied": c.setpoints,
            "voltage_msgs_applied": c.voltages, "stale_setpoints": c.stale_setpoints,
            "clear_errors_sent": c.clear_errors_sent, "lockstep_resends": c.lockstep_resends,
            "lockstep_startup_resends": c.lockstep_startup_resends,
            "commands_sent": c.commands_sent, "arrival_commands": c.arrival_commands, "payload_rejected": self.payloads.as_dict()["rejected_total"],
            "unexpected_payloads": c.unexpected_payloads, "controller_restarts": c.controller_restarts,
            "setpoints_out_of_envelope": self.envelope.rejected,
            "bus_errors": c.bus_errors,
            "uplink_dropped": up.dropped, "downlink_dropped": down.dropped, "saturated_steps": self.inner.saturated_steps,
            "seq_lost": self.sp_seq.lost, "seq_reordered": self.sp_seq.reordered, "seq_duplicates": self.sp_seq.duplicates,
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
                   uplink_pending=self.uplink.pending)
        return out

    def publish_stats(self, final: bool = False) -> None:
        d = self.stats_dict()
        d["final"] = final
        self.stats_pub.put(json.dumps(d).encode())

    def close(self) -> None:
        for sub in (self.sp_sub, self.v_sub, self.ack_sub):
            sub.undeclare()

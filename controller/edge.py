"""The edge node: the I/O shell of the edge's pure core (`EdgeCore`, controller/edge_core.py) next to the driver,
which runs the backstepping inner loop at the driver's feedback rate with the latest setpoint v_x(t_i) held.

The shell receives CAN frames (`on_can`) and Zenoh payloads, hands them to the core with their receive times, meets
the controller as its clock says (`sync`: real time or lockstep, `sea_hil.runtime`), sends the frames the core
returns and publishes its states, tracking records and `/stats`. Per feedback sample: the core accepts it and
publishes its state (uplink link emulator), the clock syncs, the core takes the setpoints the downlink emulator
releases and answers with the VOLTAGE_CMD (and CLEAR_ERRORS when setpoints are fresh again). Link emulation runs in
the core for both directions, clocked by the driver's sample time (1 ms resolution), so lockstep runs are
deterministic (an answer to state k takes effect no earlier than k's sample time + uplink + downlink delay, in
simulated time, `sim_latency_us_*`, at no cost in wall time).

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
from collections.abc import Callable
from typing import Any

import can
import zenoh

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_core import CommandFrames, EdgeCore
from sea_hil.errors import BusError, ConfigError
from sea_hil.protocol.can_frames import Feedback
from sea_hil.protocol.canbus import CanHandle, recv_pending, rx_monotonic_ns, send_with_retry
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.zsession import publisher
from sea_hil.runtime.clock import Clock, EdgeSync, RealTimeClock
from sea_hil.runtime.node import Node

log = logging.getLogger("sea_hil.edge")


class EdgeNode(Node):
    kind = "edge"

    def __init__(self, cfg: SeaHilConfig, bus: CanHandle, session: zenoh.Session, node_id: int, *,
                 inner: str = "edge", clock: Clock | None = None, mode: str = "et",
                 commands: CommandFrames | None = None) -> None:
        """`commands`: how the core's answers become CAN frames (None: the sea profile's VOLTAGE_CMD and CLEAR_ERRORS
        through the DBC; the CiA 402 edge passes its CANopen master's, controller/cia402_edge.py)."""
        if inner not in ("edge", "remote"):
            raise ValueError("inner must be 'edge' or 'remote'")
        if cfg.trigger.placement == "edge" and (inner != "edge" or mode not in ("et", "tt")):
            raise ConfigError("trigger.placement = 'edge' needs the inner loop at the edge and --controller et|tt")
        super().__init__()
        self.cfg, self.bus, self.node_id = cfg, bus, node_id
        self.keys = Keys.from_config(cfg.zenoh)
        self.lock = threading.Lock()       # feedback path vs. setpoint arrival (Zenoh callback thread)
        self.sync: EdgeSync = (clock or RealTimeClock()).edge(self)
        self.state_pub = publisher(session, self.keys.state, congestion_control=self.sync.congestion_control)
        self.event_pub = publisher(session, self.keys.event, express=False,
                                   congestion_control=zenoh.CongestionControl.BLOCK) \
            if cfg.trigger.placement == "edge" else None
        self.core = EdgeCore(cfg, node_id, inner=inner, mode=mode, state_sink=self.state_pub.put,
                             record_sink=self._publish_record, stamp=self.sync.state_stamp,
                             restart_possible=self.sync.restart_possible, commands=commands)
        self.stats_pub = publisher(session, self.keys.stats, express=False)
        self.send_retries = cfg.can.send_retries
        self._subs = [session.declare_subscriber(self.keys.setpoint, self.sync.downlink_callback("setpoint")),
                      session.declare_subscriber(self.keys.voltage, self.sync.downlink_callback("voltage")),
                      session.declare_subscriber(self.keys.control, self.sync.control_callback())]

    # ---- the node hooks -------------------------------------------------------------------------------------------
    def _step(self) -> bool:
        got = receive_all_stamped(self.bus, self.stop_event, self._bus_error)
        for msg, rx_ns in got:
            self.on_can(msg, rx_ns)
        return bool(got)

    def _bus_error(self, err: Exception) -> None:
        self.core.counters.bus_errors += 1
        log.warning("CAN receive failed: %s", err)

    def _close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        if self.event_pub is not None:
            self.event_pub.undeclare()

    def _stats(self) -> dict[str, float]:
        out = self.core.stats()
        out["lockstep"] = int(self.sync.lockstep)   # the record's envelope: what kind of run a recording holds
        timing = getattr(self.bus, "timing_stats", None)   # [can] emulate_bitrate: queueing delay per CAN id
        if timing is not None:
            out.update(timing())
        return out

    # ---- CAN side -------------------------------------------------------------------------------------------------
    def send(self, msg: can.Message) -> None:
        try:
            send_with_retry(self.bus, msg, self.send_retries, 0.0002)
        except BusError as err:
            self.core.counters.bus_errors += 1
            log.warning("%s", err)

    def on_can(self, msg: can.Message, now_ns: int) -> None:
        """Handle one received CAN frame (`now_ns`: its monotonic receive time, the start of the loop time of the
        sample it completes). Malformed frames are counted (`rejected_frames`), logged and ignored (`EdgeCore.on_frame`,
        which also explains a drive latch once)."""
        fb = self.core.on_frame(msg)
        if fb is not None:
            with self.lock:
                self._on_feedback(fb, now_ns)

    def _on_feedback(self, fb: Feedback, rx_ns: int) -> None:
        if self._send(self.core.on_feedback(fb, rx_ns, self.sync)):
            self.core.commanded(time.monotonic_ns() - rx_ns)

    def _send(self, frames: list[can.Message] | None) -> bool:
        for msg in frames or ():
            self.send(msg)
        return frames is not None

    def _publish_record(self, record: dict[str, Any]) -> None:
        self.event_pub.put(json.dumps(record).encode())  # type: ignore[union-attr]

    # ---- Zenoh side -----------------------------------------------------------------------------------------------
    def on_arrival(self, data: bytes, rx_ns: int, channel: str | None = None) -> None:
        """Real time: handle a setpoint/voltage payload from key `channel` when it arrives (`on_downlink`) and, if the
        downlink emulator releases it at once, apply it and send the voltage it gives with the newest feedback."""
        core = self.core
        with self.lock:
            if self.stop_event.is_set() or not self.on_downlink(data, rx_ns, channel) or core.last_fb is None:
                return
            if self.take_downlink(core.sample_t_ns) and self._send(core.respond(core.last_fb, core.last_rx_ns,
                                                                                 self.sync)):
                core.counters.arrival_commands += 1

    def on_downlink(self, data: bytes, rx_ns: int | None = None, channel: str | None = None) -> bool:
        """Handle one setpoint/voltage payload from Zenoh key `channel` (None: the inner placement's; `rx_ns`:
        monotonic arrival time); True if it entered the downlink emulator."""
        return self.core.on_downlink(data, rx_ns, channel)

    def on_ack(self, data: bytes) -> bool:
        """Handle one payload from the control key (lockstep ACKs; counted and dropped otherwise)."""
        return bool(self.sync.on_ack(data))

    def take_downlink(self, now: int) -> bool:
        """Apply the setpoints/voltages the downlink emulator releases by sample time `now`; True if any."""
        self.sync.drain()
        return self.core.take_downlink(now)


def receive_stamped(bus: Any, stop_event: Any, on_error: Callable[[Exception], None],
                    timeout_s: float = 0.05) -> tuple[Any, int] | None:
    """One frame from `bus` and its monotonic arrival time (`rx_monotonic_ns`), or None after `timeout_s` without
    one. A receive error (e.g. the interface went down) goes to `on_error` (count, log), then waits `timeout_s` on
    `stop_event` and returns None: the node keeps running."""
    try:
        msg = bus.recv(timeout=timeout_s)
    except (can.CanError, OSError) as err:
        on_error(err)
        stop_event.wait(timeout_s)
        return None
    if msg is None:
        return None
    return msg, rx_monotonic_ns(msg.timestamp, time.monotonic_ns(), time.time_ns())


def receive_all_stamped(bus: Any, stop_event: Any, on_error: Callable[[Exception], None],
                        timeout_s: float = 0.05) -> list[tuple[Any, int]]:
    """`receive_stamped`, then every frame queued behind the first (`canbus.recv_pending`) in the same wake, all
    stamped from one pair of clock reads: a node wakes once per batch (a driver tick's frames of every limb), not
    once per frame. [] after `timeout_s` without a frame or on a receive error (as `receive_stamped`: counted,
    backed off). A simulated (lockstep bus-timing) handle gives one frame per call: its reads move simulated time."""
    got = receive_stamped(bus, stop_event, on_error, timeout_s)
    if got is None:
        return []
    if getattr(bus, "simulated", False):
        return [got]
    try:
        more = recv_pending(bus)
    except (can.CanError, OSError) as err:
        on_error(err)
        return [got]
    if not more:
        return [got]
    mono_now_ns, wall_now_ns = time.monotonic_ns(), time.time_ns()
    return [got, *((m, rx_monotonic_ns(m.timestamp, mono_now_ns, wall_now_ns)) for m in more)]

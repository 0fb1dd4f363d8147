"""The SEA driver node: owns a CAN bus, serves one or more limbs (node ids) with `DriverCore`, sends feedback on a
drift-free schedule (absolute deadlines) and heartbeats. Malformed frames are rejected, counted and logged;
well-formed ids of nodes it does not serve are ignored like drive firmware's acceptance filter does (`is_foreign`,
counted in `TickStats.foreign_frames`).

Real-time mode: one tick per feedback period; waiting for the next deadline is done in `bus.recv(timeout)` so
commands are handled as they arrive and act from their arrival time within the period (`DriverCore`). Lateness of
each tick is recorded; a tick later than one period is an overrun (the schedule skips ahead, never bunches up).
Lockstep mode: the driver integrates sample k -> k+1 only once the voltage command answering feedback k (same 8-bit
seq) has arrived for every node; the last feedback is re-sent every `resend_s` of wall time while waiting, so a peer
that joins late or a lost frame does not stall the session.
"""
from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable, Container

import can

from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.integrator import prepare_advance
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import CMD_BITS, CMD_MASK, NODE_ID_MAX, NODE_ID_MIN, ErrorFlags, Feedback, VoltageCmd
from sea_hil.protocol.canbus import send_with_retry
from sea_hil.config import SeaHilConfig
from sea_hil.errors import BusError, MalformedFrame
from sea_hil.stats.histogram import LogHistogram
from sea_hil.mechanics import limb_params

log = logging.getLogger("sea_hil.plant")


@dataclass
class TickStats:
    ticks: int = 0
    overruns: int = 0
    send_retries: int = 0
    send_failures: int = 0
    bus_errors: int = 0
    foreign_frames: int = 0   # well-formed ids of node ids this node does not serve: ignored, not rejected


def command_ids() -> frozenset[int]:
    """The command ids (low `CMD_BITS` of the CAN id) the DBC defines."""
    return frozenset(m.frame_id & CMD_MASK for m in load_database().messages)


def is_foreign(msg: can.Message, served: Container[int], cmd_ids: frozenset[int]) -> bool:
    """True for a classic data frame whose 11-bit id names a DBC command of a valid node id not in `served`: the
    id alone decides (an acceptance filter never looks at another node's payload)."""
    if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.is_fd:
        return False
    node_id = msg.arbitration_id >> CMD_BITS
    return (0 <= msg.arbitration_id <= 0x7FF and NODE_ID_MIN <= node_id <= NODE_ID_MAX and node_id not in served
            and msg.arbitration_id & CMD_MASK in cmd_ids)


class PlantNode:
    def __init__(self, cfg: SeaHilConfig, bus: can.BusABC, node_ids: tuple[int, ...], *, lockstep: bool = False,
                 resend_s: float = 0.05) -> None:
        if not node_ids:
            raise BusError("plant needs at least one node id")
        self.cfg = cfg
        self.bus = bus
        self.codec = SeaCodec(node_ids)
        self.cmd_ids = command_ids()
        self.lockstep = lockstep
        self.resend_ns = int(resend_s * 1e9)
        p = limb_params(cfg.plant)
        cc = cfg.can
        self.period_ns = int(round(1e9 / cc.feedback_rate_hz))
        self.drivers = {n: DriverCore.create(n, p, 1.0 / cc.feedback_rate_hz, cc.watchdog_timeout_s, cfg.sim.substeps,
                                             tuple(cfg.plant.initial_theta_rad), make_disturbance(cfg.disturbance),
                                             DriveLimits.from_config(cfg.safety.drive))
                        for n in node_ids}
        self.heartbeat_every = max(1, int(round(cc.feedback_rate_hz / cc.heartbeat_rate_hz)))
        self.lateness = LogHistogram()
        self.stats = TickStats()
        self.stop_event = threading.Event()
        self._answered: set[int] = set()

    # ---- frames -------------------------------------------------------------------------------------------------
    def _on_message(self, msg: can.Message, now_ns: int) -> None:
        if msg.arbitration_id >> CMD_BITS not in self.drivers and is_foreign(msg, self.drivers, self.cmd_ids):
            self.stats.foreign_frames += 1   # another driver's traffic on a shared bus
            return
        try:
            frame = self.codec.decode(msg)
        except MalformedFrame as err:
            node = msg.arbitration_id >> CMD_BITS
            target = self.drivers.get(node) or next(iter(self.drivers.values()))
            target.reject()
            log.info("rejected frame: %s", err)
            return
        drv = self.drivers.get(frame.node_id)
        if drv is None or not hasattr(frame, "node_id"):
            return
        if not drv.handle(frame, now_ns):
            return  # feedback/heartbeat (a driver's own output, never a command to it): nothing to do
        if self.lockstep and isinstance(frame, VoltageCmd) and frame.seq == drv.seq & 0xFF:
            self._answered.add(frame.node_id)

    def _send(self, msg: can.Message) -> None:
        try:
            self.stats.send_retries += send_with_retry(self.bus, msg, self.cfg.can.send_retries, 0.0002)
        except BusError as err:
            self.stats.send_failures += 1
            self._bus_error(str(err))

    def _bus_error(self, what: str) -> None:
        """Flag BUS_ERROR on every driver and count; log the first error and every 1000th (no log flood)."""
        for drv in self.drivers.values():
            drv.flags |= ErrorFlags.BUS_ERROR
        self.stats.bus_errors += 1
        if self.stats.bus_errors == 1 or self.stats.bus_errors % 1000 == 0:
            log.warning("%s (%d bus errors so far)", what, self.stats.bus_errors)

    def _publish(self, drv: DriverCore, feedback: Feedback) -> None:
        try:
            msgs = self.codec.encode_feedback(feedback, saturate=True)
        except MalformedFrame as err:   # e.g. a diverged (NaN) model: report, keep the node alive
            self.stats.send_failures += 1
            log.error("node %d: feedback not encodable: %s", drv.node_id, err)
            return
        for m in msgs:
            self._send(m)

    def _publish_sample(self, drv: DriverCore, feedback: Feedback) -> None:
        """Real time: the new period starts when its sample's feedback leaves (commands act from their arrival)."""
        drv.period_start_ns = time.monotonic_ns()
        self._publish(drv, feedback)

    def _heartbeats(self) -> None:
        for drv in self.drivers.values():
            self._send(self.codec.encode(drv.heartbeat()))

    # ---- loops --------------------------------------------------------------------------------------------------
    def run(self, duration_s: float | None = None) -> None:
        if not self.lockstep:   # real time: the compiled RK4 kernel (~4x cheaper per tick) is loaded before the
            for drv in self.drivers.values():   # schedule starts, never in a period; lockstep skips it, as loading
                prepare_advance(drv.params)     # numba (~0.6 s) costs more wall time than it saves in one cycle
        (self._run_lockstep if self.lockstep else self._run_realtime)(duration_s)

    def _drain_until(self, deadline_ns: int, done: Callable[[], bool] | None = None) -> None:
        while done is None or not done():
            now = time.monotonic_ns()
            remaining = deadline_ns - now
            if remaining <= 0:
                return
            try:
                msg = self.bus.recv(timeout=remaining * 1e-9)
            except (can.CanError, OSError) as err:   # e.g. interface down: flag, count, keep the schedule
                self._bus_error(f"CAN receive failed: {err}")
                self.stop_event.wait(min(remaining * 1e-9, 0.01))
                continue
            if msg is not None:
                self._on_message(msg, time.monotonic_ns())

    def _run_realtime(self, duration_s: float | None) -> None:
        start = time.monotonic_ns()
        end = None if duration_s is None else start + int(duration_s * 1e9)
        for drv in self.drivers.values():
            drv.last_cmd_ns = start
            self._publish_sample(drv, drv.feedback())
        k, next_heartbeat_k = 0, self.heartbeat_every
        while not self.stop_event.is_set():
            k += 1
            deadline = start + k * self.period_ns
            self._drain_until(deadline)
            now = time.monotonic_ns()
            late = now - deadline
            self.lateness.record(max(late, 0) * 1e-9 + 1e-7)
            missed = late // self.period_ns if late > self.period_ns else 0
            self.stats.overruns += missed
            k += missed
            self.stats.ticks += 1
            for drv in self.drivers.values():
                if missed:
                    drv.note_overruns(missed)
                drv.check_watchdog(now)
                self._publish_sample(drv, drv.step())
            if k >= next_heartbeat_k:  # skipped ticks must not skip the heartbeat
                self._heartbeats()
                next_heartbeat_k = (k // self.heartbeat_every + 1) * self.heartbeat_every
            if end is not None and now >= end:
                break

    def _run_lockstep(self, duration_s: float | None) -> None:
        end_seq = None if duration_s is None else int(round(duration_s * 1e9 / self.period_ns))
        while not self.stop_event.is_set():
            self._answered.clear()
            for drv in self.drivers.values():
                self._publish(drv, drv.feedback())
            while len(self._answered) < len(self.drivers) and not self.stop_event.is_set():
                before = len(self._answered)
                self._drain_until(time.monotonic_ns() + self.resend_ns,
                                  lambda: len(self._answered) >= len(self.drivers))
                if len(self._answered) == before:   # nothing new within resend_s: re-send what is missing
                    for n, drv in self.drivers.items():
                        if n not in self._answered:
                            self._publish(drv, drv.feedback())
            if self.stop_event.is_set():
                break
            for drv in self.drivers.values():
                drv.last_cmd_ns = drv.sample_t_ns
                drv.step()
            self.stats.ticks += 1
            if self.stats.ticks % self.heartbeat_every == 0:
                self._heartbeats()
            if end_seq is not None and self.stats.ticks >= end_seq:
                break

    def stop(self) -> None:
        self.stop_event.set()

"""The SEA driver node: owns a CAN bus, serves one or more limbs (node ids) with `DriverCore` (the pure firmware core),
on the schedule of its clock (`sea_hil.runtime`), and sends heartbeats. Malformed frames are rejected, counted and
logged; well-formed ids of nodes it does not serve are ignored like drive firmware's acceptance filter does
(`is_foreign`, counted in `TickStats.foreign_frames`).

Real-time clock: one tick per feedback period on a drift-free schedule (absolute deadlines), one wake per tick: the
driver sleeps to the deadline, then handles every frame queued meanwhile (`take_pending`), each at its arrival time
(its bus stamp), so a command acts from its arrival within the period (`DriverCore`) as if handled when it came; all
limbs are integrated in one step and all the tick's frames leave in one send right before the driver sleeps (`publish_samples`, `wait_until`). Lateness is
recorded, a tick later than one period is an overrun. Lockstep clock
(`sea_hil.runtime.lockstep`): a sample is integrated once every served node's command for it has arrived.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable, Container
from dataclasses import dataclass

import can

from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import BusError, MalformedFrame
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.batch import prepare_batch, step_all
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.integrator import prepare_advance
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import CMD_BITS, CMD_MASK, NODE_ID_MAX, NODE_ID_MIN, ErrorFlags, Feedback
from sea_hil.protocol.canbus import CanHandle, batches, recv_pending, rx_monotonic_ns, send_all, send_with_retry
from sea_hil.protocol.timed_bus import TimedBus
from sea_hil.runtime.clock import Clock, Pacer, RealTimeClock
from sea_hil.runtime.node import Node
from sea_hil.stats.histogram import LogHistogram

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
    """True for a data frame (classic or FD) whose 11-bit id names a DBC command of a valid node id not in `served`:
    the id alone decides (an acceptance filter never looks at another node's payload)."""
    if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
        return False
    node_id = msg.arbitration_id >> CMD_BITS
    return (0 <= msg.arbitration_id <= 0x7FF and NODE_ID_MIN <= node_id <= NODE_ID_MAX and node_id not in served
            and msg.arbitration_id & CMD_MASK in cmd_ids)


class PlantNode(Node):
    kind = "plant"

    def __init__(self, cfg: SeaHilConfig, bus: CanHandle, node_ids: tuple[int, ...], *,
                 clock: Clock | None = None) -> None:
        if not node_ids:
            raise BusError("plant needs at least one node id")
        super().__init__()
        self.cfg = cfg
        self.bus = bus
        # lockstep bus-timing model: simulated arrival times
        self.sim: TimedBus | None = bus if isinstance(bus, TimedBus) and bus.simulated else None
        self.codec = SeaCodec.for_bus(cfg.can, node_ids)
        self.cmd_ids = command_ids()
        p = limb_params(cfg.plant)
        cc = cfg.can
        self.period_ns = int(round(1e9 / cc.feedback_rate_hz))
        self.drivers = {n: DriverCore.create(n, p, 1.0 / cc.feedback_rate_hz, cc.watchdog_timeout_s, cfg.sim.substeps,
                                             cfg.plant.initial_theta_rad, make_disturbance(cfg.disturbance),
                                             DriveLimits.from_config(cfg.safety.drive))
                        for n in node_ids}
        self.heartbeat_every = max(1, int(round(cc.feedback_rate_hz / cc.heartbeat_rate_hz)))
        self.lateness = LogHistogram()
        self.stats = TickStats()
        self._outbox: list[can.Message] = []        # real time: the tick's frames, sent by `send_pending`
        self._starting: list[DriverCore] = []       # the drivers whose new period starts when they leave
        self.pacer: Pacer = (clock or RealTimeClock()).plant(self)

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
        self.pacer.on_command(frame, drv)

    def _send(self, msg: can.Message) -> None:
        try:
            self.stats.send_retries += send_with_retry(self.bus, msg, self.cfg.can.send_retries, 0.0002)
        except BusError as err:
            self.stats.send_failures += 1
            self._bus_error(str(err), msg.arbitration_id >> CMD_BITS)

    def _bus_error(self, what: str, node_id: int | None = None) -> None:
        """Flag BUS_ERROR on every driver on the failed bus (a `MergedBus` serves several: with `node_id`, only
        those on that node's bus; else all) and count; log the first error and every 1000th (no log flood)."""
        routes = getattr(self.bus, "routes", None)
        bus = routes.get(node_id) if routes is not None and node_id is not None else None
        for n, drv in self.drivers.items():
            if bus is None or routes is not None and routes.get(n) is bus:
                drv.flags |= ErrorFlags.BUS_ERROR
        self.stats.bus_errors += 1
        if self.stats.bus_errors == 1 or self.stats.bus_errors % 1000 == 0:
            log.warning("%s (%d bus errors so far)", what, self.stats.bus_errors)

    def publish(self, drv: DriverCore, feedback: Feedback) -> None:
        if self.sim is not None:   # the sample's frames leave at its sample time; commands act from their arrival
            self.sim.advance_sim_time(drv.sample_t_ns)
            drv.period_start_ns = drv.sample_t_ns
        try:
            msgs = self.codec.encode_feedback(feedback, saturate=True)
        except MalformedFrame as err:   # e.g. a diverged (NaN) model: report, keep the node alive
            self.stats.send_failures += 1
            log.error("node %d: feedback not encodable: %s", drv.node_id, err)
            return
        for m in msgs:
            self._send(m)

    def publish_samples(self, samples: list[tuple[DriverCore, Feedback]], heartbeats: bool = False) -> None:
        """Real time: every limb's new sample (and with `heartbeats` each drive's HEARTBEAT) encoded for one send of
        all the tick's frames, which `send_pending` makes (`wait_until` just before it sleeps)."""
        frames = self._outbox
        for drv, feedback in samples:
            try:
                frames += self.codec.encode_feedback(feedback, saturate=True)
            except MalformedFrame as err:   # e.g. a diverged (NaN) model: report, keep the node alive
                self.stats.send_failures += 1
                log.error("node %d: feedback not encodable: %s", drv.node_id, err)
            self._starting.append(drv)
        if heartbeats:
            frames += [self.codec.encode(drv.heartbeat()) for drv in self.drivers.values()]

    def send_pending(self) -> None:
        """Send the frames `publish_samples` encoded, in one `canbus.send_all` (one wake of each reader where the bus
        batches; frame by frame, each with its retries, on other buses); the new periods start as they leave."""
        frames, self._outbox = self._outbox, []
        start_ns = time.monotonic_ns()
        for drv in self._starting:
            drv.period_start_ns = start_ns
        self._starting = []
        self.send_frames(frames)

    def send_frames(self, frames: list[can.Message]) -> None:
        """`frames` in one `canbus.send_all` where the bus batches, else frame by frame (each with its retries); a
        failed send is counted and reported, the node lives on."""
        if not frames:
            return
        if not batches(self.bus):
            for m in frames:
                self._send(m)
            return
        try:
            send_all(self.bus, frames)
        except (can.CanError, OSError) as err:
            self.stats.send_failures += 1
            self._bus_error(f"CAN send failed: {err}")

    def wait_until(self, deadline_ns: int) -> None:
        """Real time: send the tick's frames (`send_pending`), then sleep until `deadline_ns` (monotonic) at once, so
        a reader woken by them finds the GIL free; no frame wakes the driver (`take_pending` reads them)."""
        self.send_pending()
        remaining = deadline_ns - time.monotonic_ns()
        if remaining > 0:
            time.sleep(remaining * 1e-9)

    def take_pending(self, mono_now_ns: int) -> None:
        """Real time: handle every frame queued since the last tick, each at its arrival time (its bus stamp,
        `canbus.rx_monotonic_ns`), so a command acts from its arrival within the period as if it had been handled
        then (`DriverCore`): one pass per tick instead of one wake per frame."""
        try:
            msgs = recv_pending(self.bus)
        except (can.CanError, OSError) as err:   # e.g. interface down: flag, count, keep the schedule
            self._bus_error(f"CAN receive failed: {err}")
            return
        if msgs:
            wall_now_ns = time.time_ns()
            for msg in msgs:
                self._on_message(msg, rx_monotonic_ns(msg.timestamp, mono_now_ns, wall_now_ns))

    def heartbeats(self) -> None:
        if self.sim is not None:
            self.sim.advance_sim_time(max(drv.sample_t_ns for drv in self.drivers.values()))
        for drv in self.drivers.values():
            self._send(self.codec.encode(drv.heartbeat()))

    def prepare_kernels(self) -> None:
        """Load the compiled RK4 kernels (~4x cheaper per tick; with several limbs the batch kernel, one call for all)
        before a real-time schedule starts, never in a period."""
        drv = next(iter(self.drivers.values()))
        prepare_advance(drv.params)
        if len(self.drivers) > 1:
            prepare_batch(drv.params)

    def step_drivers(self) -> list[tuple[DriverCore, Feedback]]:
        """Integrate one period of every served limb (one compiled call for all when loaded, `plant_emulator.batch`)
        and return each driver with its new sample's feedback, in node-id order of `drivers`."""
        drivers = list(self.drivers.values())
        return list(zip(drivers, step_all(drivers), strict=True))

    def drain_until(self, deadline_ns: int, done: Callable[[], bool] | None = None) -> None:
        """Handle received frames until `deadline_ns` (monotonic) or until `done()`."""
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
                self._on_message(msg, self.sim.rx_time_ns if self.sim is not None else time.monotonic_ns())

    # ---- the node hooks -----------------------------------------------------------------------------------------
    def _on_start(self, duration_s: float | None) -> None:
        self.pacer.start(duration_s)

    def _step(self) -> bool:
        self.pacer.tick()
        return True

    def _on_stop(self) -> None:
        self.send_pending()   # real time: the last tick's frames (nothing is pending in lockstep)

    def finished(self) -> bool:
        return bool(self.pacer.done)

    def _stats(self) -> dict[str, float]:
        s, lat = self.stats, self.lateness.to_dict()
        out: dict[str, float] = {"ticks": s.ticks, "overruns": s.overruns, "send_retries": s.send_retries,
                                 "send_failures": s.send_failures, "bus_errors": s.bus_errors,
                                 "foreign_frames": s.foreign_frames}
        for k in ("p50", "p99", "max"):
            out[f"lateness_us_{k}"] = v * 1e6 if (v := lat[k]) is not None else -1.0
        for n, drv in self.drivers.items():
            c = drv.counters
            out.update({f"node{n}_rejected_frames": c.rejected_frames, f"node{n}_ignored_commands": c.ignored_commands,
                        f"node{n}_commands": c.commands, f"node{n}_watchdog_trips": c.watchdog_trips,
                        f"node{n}_state": int(drv.state)})
        return out

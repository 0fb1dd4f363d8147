"""The CiA 402 drive node: the I/O shell around `Cia402Limb` cores (one per limb, two CANopen nodes each) on one CAN
bus. It waits in `bus.recv` until the next thing due (a plant sample, a heartbeat, an event timer), hands every
received frame to the limbs whose nodes it addresses (NMT and SYNC reach all), and sends what they answer. Frames
for no node here are ignored and counted (`foreign_frames`); a failed send is counted and reported by the nodes as
an EMCY (0x8110). Time comes from `now_ns` (monotonic by default; tests pass a clock they advance themselves); with
`lockstep` it is simulated: one period per SYNC received (the master answers each SYNC before it sends the next, so
the plant integrates one sample per answered SYNC, as the sea profile's lockstep pacer does per answered feedback).
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import can

from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import BusError, ConfigError
from sea_hil.plant_emulator.canopen_slave import Frame
from sea_hil.plant_emulator.cia402_drive import Cia402Limb
from sea_hil.plant_emulator.integrator import prepare_advance
from sea_hil.protocol.canbus import CanHandle, send_with_retry
from sea_hil.runtime.node import Node

log = logging.getLogger("sea_hil.plant")
MAX_WAIT_S = 0.05


@dataclass
class Cia402Stats:
    received: int = 0
    sent: int = 0
    foreign_frames: int = 0
    send_failures: int = 0
    bus_errors: int = 0
    ticks: int = 0          # plant samples integrated (the first limb's)
    overruns: int = 0       # real time: periods integrated late, more than one at once


def limb_node_ids(node_ids: tuple[int, ...]) -> list[tuple[int, int]]:
    if len(node_ids) % 2:
        raise ConfigError(f"cia402 node ids come in (hip, knee) pairs, got {node_ids}")
    return [(node_ids[i], node_ids[i + 1]) for i in range(0, len(node_ids), 2)]


class Cia402PlantNode(Node):
    kind = "plant"

    def __init__(self, cfg: SeaHilConfig, bus: CanHandle, node_ids: tuple[int, ...] | None = None, *,
                 now_ns: Callable[[], int] = time.monotonic_ns, jit: bool = True, lockstep: bool = False) -> None:
        super().__init__()
        self.cfg, self.bus, self.now_ns = cfg, bus, now_ns
        self.lockstep, self.sim_t_ns = lockstep, 0
        if lockstep:
            self.now_ns = lambda: self.sim_t_ns
        self.limbs = [Cia402Limb.create(cfg, pair) for pair in limb_node_ids(node_ids or cfg.can.cia402.node_ids)]
        self.stats = Cia402Stats()
        if jit:
            prepare_advance(self.limbs[0].driver.params)

    def _on_start(self, duration_s: float | None) -> None:
        t = self.now_ns()
        for limb in self.limbs:
            self._send(limb, limb.start(t))

    def _send(self, limb: Cia402Limb, frames: list[Frame]) -> None:
        for f in frames:
            msg = can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False)
            try:
                send_with_retry(self.bus, msg, self.cfg.can.send_retries, 0.0002)
                self.stats.sent += 1
            except BusError as err:
                self.stats.send_failures += 1
                if self.stats.send_failures == 1 or self.stats.send_failures % 1000 == 0:
                    log.warning("cia402 send failed: %s (%d so far)", err, self.stats.send_failures)
                limb.note_bus_error(self.now_ns())   # its EMCY may not get out either: counted, not retried

    def handle(self, msg: can.Message) -> None:
        """One received frame, at the current time."""
        if msg.is_error_frame:
            self.stats.bus_errors += 1
            return
        self.stats.received += 1
        f = Frame(msg.arbitration_id, bytes(msg.data), bool(msg.is_remote_frame), bool(msg.is_extended_id))
        if self.lockstep and f.can_id == 0x080 and not f.extended:
            self.sim_t_ns += self.limbs[0].period_ns
        t = self.now_ns()
        hit = False
        for limb in self.limbs:
            if f.can_id <= 0x7FF and limb.owns(f):
                hit = True
                self._send(limb, limb.receive(f, t))
        if not hit:
            self.stats.foreign_frames += 1
        self.stats.ticks = self.limbs[0].driver.seq

    def tick(self) -> None:
        """Everything due by now (plant samples, heartbeats, timers)."""
        t = self.now_ns()
        for limb in self.limbs:
            before = limb.driver.seq
            self._send(limb, limb.due(t))
            self.stats.overruns += max(0, limb.driver.seq - before - 1) if not self.lockstep else 0
        self.stats.ticks = self.limbs[0].driver.seq

    def _step(self) -> bool:
        self.tick()
        wait_ns = min(limb.next_deadline_ns() for limb in self.limbs) - self.now_ns()
        try:
            msg = self.bus.recv(timeout=min(max(wait_ns, 0) * 1e-9, MAX_WAIT_S))
        except (can.CanError, OSError) as err:
            self.stats.bus_errors += 1
            log.warning("CAN receive failed: %s", err)
            self.stop_event.wait(0.01)
            return False
        if msg is None:
            return False
        self.handle(msg)
        return True

    def _stats(self) -> dict[str, float]:
        s = self.stats
        out: dict[str, float] = {"received": s.received, "sent": s.sent, "foreign_frames": s.foreign_frames,
                                 "send_failures": s.send_failures, "bus_errors": s.bus_errors}
        for limb in self.limbs:
            for a in limb.axes:
                n, c = a.slave.node_id, a.slave.counters
                out.update({f"node{n}_rejected_frames": c.rejected_frames, f"node{n}_sdo_aborts": c.sdo_aborts,
                            f"node{n}_emcy": c.emcy_sent, f"node{n}_state": int(a.state),
                            f"node{n}_limit_trips": a.limit_trips, f"node{n}_watchdog_trips": a.watchdog_trips,
                            f"node{n}_syncs": c.syncs, f"node{n}_tpdo2_sent": c.tpdo_sent[1]})
        return out

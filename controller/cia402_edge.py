"""The edge on a CiA 402 bus (`[can] profile = "cia402"`, one limb): the sea profile's `EdgeNode` (Zenoh
uplink and downlink, trigger, inner loop, lockstep sync with the controller) with its CAN side replaced by the
CANopen master core `Cia402Master` (the edge core answers through its `Cia402Commands`). It boots and configures both SEA nodes, then produces the SYNC: the two nodes'
TPDO 2 and 3 of a SYNC make one `Feedback` sample (the same object the DBC profile decodes), which the edge answers
as always; the answer goes out as each node's RPDO 3 (target voltage, acting on arrival), then the next SYNC. So
simulated time advances one period per answered SYNC, and the drive (`Cia402PlantNode(lockstep=True)`) takes its
time from the SYNCs it receives. In real time the edge produces the SYNC on a drift-free 1 kHz grid (missed periods
counted, `cia402_sync_misses`), answers each complete sample (and each setpoint arrival) with RPDO 3, and resets a
drive fault by controlword when setpoints are fresh again, as it clears the sea profile's (soft-limit faults are left
to the operator)."""
from __future__ import annotations

import time
from typing import Any

import can
import zenoh

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.cia402_master import Cia402Master, Frame
from sea_hil.controller.edge import EdgeNode, receive_stamped
from sea_hil.protocol.can_frames import LIMIT_FLAGS, DriverState, ErrorFlags, Feedback
from sea_hil.protocol.canbus import CanHandle
from sea_hil.protocol.cia402_od import EMCY_CODES
from sea_hil.runtime.clock import Clock
from sea_hil.runtime.lockstep import LockstepEdgeSync

LIMIT_CODES = {code for flag, code in EMCY_CODES.items() if flag & LIMIT_FLAGS}   # the drive's soft-limit EMCY codes


def _message(f: Frame) -> can.Message:
    return can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False)


class Cia402Commands:
    """The edge core's `CommandFrames` on a CiA 402 bus: the answer to a sample as RPDO 3 frames (target voltage per
    node) instead of a VOLTAGE_CMD, a (non-limit) drive fault reset by controlword (the master's SDO walk). A SYNC is
    never re-sent, so a repeated sample has no command to repeat."""

    repeatable = False

    def __init__(self, master: Cia402Master) -> None:
        self.master = master

    def command(self, u: tuple[float, float], seq: int) -> list[can.Message]:
        return [_message(f) for f in self.master.command(u)]

    def clear(self) -> list[can.Message]:
        return [_message(f) for f in self.master.fault_reset()]


class Cia402EdgeNode(EdgeNode):
    def __init__(self, cfg: SeaHilConfig, bus: CanHandle, session: zenoh.Session, node_ids: tuple[int, int], *,
                 inner: str = "edge", clock: Clock | None = None, mode: str = "et") -> None:
        self.master = Cia402Master(node_ids)
        super().__init__(cfg, bus, session, node_ids[0], inner=inner, clock=clock, mode=mode,
                         commands=Cia402Commands(self.master))
        self.lockstep = isinstance(self.sync, LockstepEdgeSync)
        self.period_ns = self.core.period_ns
        self.sync_due_ns: int | None = None     # real time: the next SYNC (a drift-free 1 / feedback_rate_hz grid)
        self.sync_misses = 0                    # real time: SYNC periods skipped (the edge was late)
        self.syncs = 0
        self._answered = True

    def _on_start(self, duration_s: float | None) -> None:
        self._send_frames(self.master.start())

    def _send_frames(self, frames: list[Frame]) -> None:
        for f in frames:
            self.send(_message(f))

    def _next_sync(self) -> None:
        self.syncs += 1
        self._answered = False
        self._send_frames(self.master.sync())

    def _step(self) -> bool:
        """Real time: the SYNC producer between receptions; lockstep: the SYNC follows each answer (`on_can`)."""
        if self.lockstep or self.sync_due_ns is None:
            return super()._step()
        now = time.monotonic_ns()
        if now >= self.sync_due_ns:
            missed = (now - self.sync_due_ns) // self.period_ns
            self.sync_misses += missed
            self.sync_due_ns += (missed + 1) * self.period_ns
            self._next_sync()
        got = receive_stamped(self.bus, self.stop_event, self._bus_error,
                              timeout_s=max(self.sync_due_ns - time.monotonic_ns(), 0) * 1e-9)
        if got is None:
            return False
        self.on_can(*got)
        return True

    def on_can(self, msg: can.Message, now_ns: int) -> None:
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            self.core.counters.rejected_frames += 1
            return
        running = self.master.phase == "run"
        self._send_frames(self.master.receive(Frame(msg.arbitration_id, bytes(msg.data))))
        core = self.core
        if self.master.drive_state is not None:   # every latch counted, as from the sea profile's heartbeats
            core.latch_log.on_heartbeat(core.sample_t_ns, self.master.drive_state)
        if running and self.master.faulted and core.driver_state is not DriverState.FAULT:
            core.driver_state = DriverState.FAULT    # the edge core clears it as the sea profile's
            codes = set(self.master.emcy_code.values())
            core.driver_flags = ErrorFlags.POSITION_LIMIT if codes & LIMIT_CODES else ErrorFlags(0)
        if not running and self.master.phase == "run" and self.sync_due_ns is None:
            if not self.lockstep:
                self.sync_due_ns = time.monotonic_ns()     # configured and enabled: the SYNC producer starts
                return
            self._next_sync()                    # configured and enabled: the first SYNC
            return
        if self._answered or msg.arbitration_id & ~0x7F not in (0x280, 0x380):
            return
        m = self.master.measurement()
        if m is None:
            return
        self._answered = True
        t_us = self.syncs * self.period_ns // 1000
        fb = Feedback(self.node_id, self.syncs & 0xFF, t_us & 0xFFFF, (m[0], m[1]), (m[2], m[3]), (m[4], m[5]),
                      (m[6], m[7]))
        with self.lock:
            self._on_feedback(fb, now_ns)
        if self.lockstep and not self.stop_event.is_set():
            self._next_sync()

    def _stats(self) -> dict[str, Any]:
        out = super()._stats()
        c = self.master.counters
        out.update({"cia402_syncs": c.syncs, "cia402_emcys": c.emcys, "cia402_faults": c.faults,
                    "cia402_sdo_aborts": c.sdo_aborts, "cia402_incomplete_syncs": c.incomplete_syncs,
                    "cia402_sync_misses": self.sync_misses, "cia402_rejected_frames": c.rejected_frames})
        return out

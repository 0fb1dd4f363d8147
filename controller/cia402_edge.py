"""The edge on a CiA 402 bus (`[can] profile = "cia402"`, lockstep only so far): the sea profile's `EdgeNode` (Zenoh
uplink and downlink, trigger, inner loop, lockstep sync with the controller) with its CAN side replaced by the
CANopen master core `Cia402Master`. It boots and configures both SEA nodes, then produces the SYNC: the two nodes'
TPDO 2 and 3 of a SYNC make one `Feedback` sample (the same object the DBC profile decodes), which the edge answers
as always; the answer goes out as each node's RPDO 3 (target voltage, acting on arrival), then the next SYNC. So
simulated time advances one period per answered SYNC, and the drive (`Cia402PlantNode(lockstep=True)`) takes its
time from the SYNCs it receives."""
from __future__ import annotations

from typing import Any

import can
import zenoh

from sea_hil.config import SeaHilConfig
from sea_hil.controller.cia402_master import Cia402Master, Frame
from sea_hil.controller.edge import EdgeNode
from sea_hil.controller.edge_command import CommandPath
from sea_hil.errors import ConfigError
from sea_hil.protocol.can_codec import Feedback
from sea_hil.runtime.clock import Clock
from sea_hil.runtime.lockstep import LockstepEdgeSync


class Cia402CommandPath(CommandPath):
    """The answer to a sample as RPDO 3 frames (target voltage per node) instead of a VOLTAGE_CMD."""

    def __init__(self, base: CommandPath, master: Cia402Master) -> None:
        super().__init__(base.bus, base.codec, base.node_id, base.inner, base.inner_mode, base.send_retries,
                         base.counters)
        self.master = master

    def answer(self, fb: Feedback, command: bool, clear: bool) -> bool:
        if not command:
            return False
        if self.inner_mode == "remote":
            u = self.voltage if self.voltage is not None else (0.0, 0.0)
        else:
            u = self.inner.voltage((*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s))  # type: ignore
        for f in self.master.command(u):
            self.send(can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False))
        self.last_cmd = None        # a SYNC is never re-sent: nothing to repeat
        return True


class Cia402EdgeNode(EdgeNode):
    def __init__(self, cfg: SeaHilConfig, bus: can.BusABC, session: zenoh.Session, node_ids: tuple[int, int], *,
                 inner: str = "edge", clock: Clock | None = None, mode: str = "et") -> None:
        super().__init__(cfg, bus, session, node_ids[0], inner=inner, clock=clock, mode=mode)
        if not isinstance(self.sync, LockstepEdgeSync):
            raise ConfigError("the cia402 profile in sea-hil run needs --lockstep (the real-time SYNC producer is "
                              "not built yet)")
        self.master = Cia402Master(node_ids)
        base: CommandPath = self.command_path   # type: ignore[has-type]
        self.command_path = Cia402CommandPath(base, self.master)
        self.syncs = 0
        self._answered = True

    def _on_start(self, duration_s: float | None) -> None:
        self._send_frames(self.master.start())

    def _send_frames(self, frames: list[Frame]) -> None:
        for f in frames:
            self.command_path.send(can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False))

    def _next_sync(self) -> None:
        self.syncs += 1
        self._answered = False
        self._send_frames(self.master.sync())

    def on_can(self, msg: can.Message, now_ns: int) -> None:
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            self.counters.rejected_frames += 1
            return
        running = self.master.phase == "run"
        self._send_frames(self.master.receive(Frame(msg.arbitration_id, bytes(msg.data))))
        if not running and self.master.phase == "run":
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
        if not self.stop_event.is_set():
            self._next_sync()

    def _stats(self) -> dict[str, Any]:
        out = super()._stats()
        c = self.master.counters
        out.update({"cia402_syncs": c.syncs, "cia402_emcys": c.emcys, "cia402_faults": c.faults,
                    "cia402_sdo_aborts": c.sdo_aborts, "cia402_incomplete_syncs": c.incomplete_syncs})
        return out

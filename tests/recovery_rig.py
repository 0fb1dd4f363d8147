"""In-process closed loop for the recovery transients (issue 19): the real `EdgeNode` (real-time clock semantics,
clocked by the drive's sample time), the emulated drive (`DriverCore`, watchdog and soft limits on) and the remote
controller's pure core (`ControllerCore`), joined without Zenoh: the edge's published states go straight to the
controller core, its setpoints straight back into `EdgeNode.on_downlink`. Faults in sample time: the controller
killed (silent) and restarted (a new core, a new epoch), the edge killed and restarted (a new `EdgeNode` on the same
drive), or the edge stalled (no frames handled, its state kept). Deterministic: no wall clock decides anything."""
from __future__ import annotations

import uuid
from dataclasses import dataclass, field
from typing import Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.remote_core import ControllerCore
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import ClearErrors, VoltageCmd
from sea_hil.protocol.epoch import new_epoch
from sea_hil.protocol.payloads import StatePayload, decode
from sea_hil.session.builder import SessionBuilder

NODE = 1


@dataclass
class Recovery:
    """Peaks after the fault is over (restart / end of the stall) and what the drive and the edge did."""
    peak_force_n: float = 0.0
    peak_velocity_rad_s: float = 0.0
    peak_voltage_v: float = 0.0
    limit_trips: int = 0
    watchdog_trips: int = 0
    resumes: int = 0
    resume_anchors: int = 0     # edge trigger: re-anchors because the drive was cleared inside the lead-in
    running_again: bool = False
    flags: list[str] = field(default_factory=list)


class RecoveryRig:
    def __init__(self, cfg: SeaHilConfig, builder: SessionBuilder) -> None:
        self.cfg, self.b = cfg, builder
        self.params = limb_params(cfg.plant)
        self.drv = DriverCore.create(NODE, self.params, 1.0 / cfg.can.feedback_rate_hz, cfg.can.watchdog_timeout_s,
                                     cfg.sim.substeps, tuple(cfg.plant.initial_theta_rad),
                                     make_disturbance(cfg.disturbance), DriveLimits.from_config(cfg.safety.drive))
        self.codec = SeaCodec([NODE])
        self.heartbeat_every = int(round(cfg.can.feedback_rate_hz / cfg.can.heartbeat_rate_hz))
        self.controller: ControllerCore | None = None
        self.edge: Any = None
        self.peer: Any = None
        self._edge_restarted = False

    def start_edge(self) -> None:
        channel = f"virtual:recovery-{uuid.uuid4().hex[:8]}"
        self.edge = self.b.edge(self.b.bus(channel), self.b.zenoh(), NODE)
        self.peer = self.b.bus(channel)
        self.edge.sync.state_sent = self._to_controller     # the uplink, without Zenoh
        self._edge_restarted = self.controller is not None

    def start_controller(self) -> None:
        self.controller = ControllerCore(self.cfg, "et", cycles=1000, epoch=new_epoch())

    def _to_controller(self, _at_ns: int, _seq: int, data: bytes) -> None:
        if self.controller is None:
            return
        p = decode(data)
        assert isinstance(p, StatePayload)
        if self._edge_restarted:        # what the controller node does on a new edge epoch (controller/remote.py)
            self.controller.restart_at(p)
            self._edge_restarted = False
        answer = self.controller.on_state(p, lambda q: q.sample_t_ns, lambda: 0)
        for _kind, payload in answer.messages if answer else ():
            self.edge.on_downlink(payload)

    def step(self, edge_alive: bool = True) -> Any:
        """One drive sample: integrate, watchdog, feedback (+ heartbeat) to the edge, its commands to the drive."""
        fb = self.drv.step()
        now = self.drv.sample_t_ns
        self.drv.check_watchdog(now)
        if not edge_alive:
            return fb
        msgs = self.codec.encode_feedback(fb, saturate=True)
        if self.drv.seq % self.heartbeat_every == 0:
            msgs.append(self.codec.encode(self.drv.heartbeat()))
        for msg in msgs:
            self.edge.on_can(msg, 0)
        while (msg := self.peer.recv(timeout=0)) is not None:
            frame = self.codec.decode(msg)
            if isinstance(frame, (VoltageCmd, ClearErrors)):
                self.drv.handle(frame, now)
        return fb

    def run(self, kind: str, fault_s: float, down_s: float, after_s: float) -> Recovery:
        """Run to `fault_s`, inject `kind` (controller | edge | stall) for `down_s`, run `after_s` more."""
        self.start_edge()
        self.start_controller()
        period_s = 1.0 / self.cfg.can.feedback_rate_hz
        n_fault, n_back = round(fault_s / period_s), round((fault_s + down_s) / period_s)
        out = Recovery()
        for k in range(n_back + round(after_s / period_s)):
            if k == n_fault and kind == "controller":
                self.controller = None
            if k == n_back and kind == "controller":
                self.start_controller()
            if k == n_back and kind == "edge":
                self.start_edge()
            fb = self.step(edge_alive=kind == "controller" or not n_fault <= k < n_back)
            if k >= n_back:
                out.peak_force_n = max(out.peak_force_n, *(abs(kk * d) for kk, d in
                                                           zip((self.params.k1, self.params.k2), fb.delta_m, strict=True)))
                out.peak_velocity_rad_s = max(out.peak_velocity_rad_s, *map(abs, fb.omega_rad_s))
                out.peak_voltage_v = max(out.peak_voltage_v, *map(abs, self.drv.voltage_v))
        c = self.drv.counters
        out.limit_trips, out.watchdog_trips, out.resumes = c.limit_trips, c.watchdog_trips, self.edge.core.counters.resumes
        out.resume_anchors = self.edge.core.events.resume_anchors if self.edge.core.events is not None else 0
        out.running_again, out.flags = self.drv.state.name == "RUNNING", [str(self.drv.flags)]
        return out

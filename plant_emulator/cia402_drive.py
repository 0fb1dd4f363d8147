"""One limb in the CiA 402 profile: two CANopen nodes (hip and knee SEA, `Cia402Axis` each) driving one plant, pure
(frames and integer-nanosecond time in, frames out; the I/O shell is `cia402_node.Cia402PlantNode`).

The plant runs on the drive's own sample grid from boot (t0 + k / `[can] feedback_rate_hz`), integrated by the
driver firmware's `DriverCore` (Eq. 1-9, RK4, the voltage held piecewise between the instants it changes, as in the
sea profile): `advance(t_ns)` integrates every whole period up to `t_ns`, then each axis sees the new sample
(actual values, soft limits, watchdog) and the nodes send what is due (heartbeat, event-driven TPDOs, EMCY). A
SYNC latches nothing new: the synchronous TPDOs carry the newest sample; synchronous RPDOs (transmission type 0-240,
the default for the targets) act at the SYNC after they arrived, event-driven ones (254/255) when they arrive.
DriverCore's own state machine, limits and watchdog are not used here: the axes fault per joint (CiA 402).
"""
from __future__ import annotations

from dataclasses import dataclass

from sea_hil.config.root import SeaHilConfig
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.canopen_slave import CanopenSlave, Frame
from sea_hil.plant_emulator.cia402_axis import Cia402Axis
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.protocol.can_frames import VoltageCmd
from sea_hil.protocol.cia402_od import joint_defaults, object_dictionary


@dataclass
class Cia402Limb:
    driver: DriverCore
    axes: tuple[Cia402Axis, Cia402Axis]
    t0_ns: int | None = None
    collected_ns: int | None = None     # the time of the last `_collect`: everything due by then is out

    @classmethod
    def create(cls, cfg: SeaHilConfig, node_ids: tuple[int, int]) -> Cia402Limb:
        p = limb_params(cfg.plant)
        cc = cfg.can
        driver = DriverCore.create(node_ids[0], p, 1.0 / cc.feedback_rate_hz, cc.watchdog_timeout_s, cfg.sim.substeps,
                                   cfg.plant.initial_theta_rad, make_disturbance(cfg.disturbance))
        axes = []
        for joint, node_id in enumerate(node_ids):
            axis = Cia402Axis(joint, p)
            axis.slave = CanopenSlave(node_id, object_dictionary(joint_defaults(cfg, joint)), axis)
            axes.append(axis)
        return cls(driver, (axes[0], axes[1]))

    @property
    def node_ids(self) -> tuple[int, int]:
        return (self.axes[0].slave.node_id, self.axes[1].slave.node_id)

    @property
    def period_ns(self) -> int:
        return self.driver.period_ns

    def sample_ns(self, seq: int | None = None) -> int:
        """Time of sample `seq` (default: the newest)."""
        assert self.t0_ns is not None
        return self.t0_ns + (self.driver.seq if seq is None else seq) * self.driver.period_ns

    def start(self, t_ns: int) -> list[Frame]:
        """Power on at `t_ns`: the plant's sample 0, both nodes' boot-up messages."""
        self.t0_ns = t_ns
        self.driver.period_start_ns = t_ns
        out: list[Frame] = []
        for a in self.axes:
            out += a.slave.boot(t_ns)
            a.on_sample(self.driver.feedback(), self.driver.x[4 + a.joint], t_ns)
        return out + self._collect(t_ns)

    def owns(self, f: Frame) -> bool:
        return f.can_id <= 0x7FF and any(a.slave.owns(f.can_id) for a in self.axes)

    def receive(self, f: Frame, t_ns: int) -> list[Frame]:
        """One frame at `t_ns` (the plant is first brought up to `t_ns`)."""
        out = self.advance(t_ns)
        for a in self.axes:
            if f.can_id <= 0x7FF and a.slave.owns(f.can_id):
                out += a.slave.receive(f, t_ns)
        return out + self._collect(t_ns)

    def advance(self, t_ns: int) -> list[Frame]:
        """Integrate every whole period that ends by `t_ns`; the frames the new samples cause."""
        out: list[Frame] = []
        d = self.driver
        while self.sample_ns(d.seq + 1) <= t_ns:
            d.period_start_ns = self.sample_ns()
            fb = d.step()
            t_sample = self.sample_ns()
            d.period_start_ns = t_sample
            for a in self.axes:
                a.on_sample(fb, d.x[4 + a.joint], t_sample)
            out += self._collect(t_sample)
        return out

    def due(self, t_ns: int) -> list[Frame]:
        """Everything due by `t_ns` with no frame received: new samples, then the time-driven output (heartbeats,
        event TPDOs and timers). Nothing to do when the last `_collect` was at `t_ns` (each `receive` and sample
        ends with one; a second at the same instant with no input in between sends nothing: the 1 kHz path's I/O
        shell calls this after every frame)."""
        out = self.advance(t_ns)
        if self.collected_ns != t_ns:
            out += self._collect(t_ns)
        return out

    def _collect(self, t_ns: int) -> list[Frame]:
        """Apply the axes' voltages from `t_ns`; their pending EMCYs and the nodes' time-driven output."""
        self.collected_ns = t_ns
        u = (self.axes[0].voltage_v, self.axes[1].voltage_v)
        if u != self.driver.voltage_v:
            self.driver.handle(VoltageCmd(self.driver.node_id, u, 0), t_ns)
        out: list[Frame] = []
        for a in self.axes:
            a.refresh_counters()
            out += a.pending
            a.pending = []
            out += a.slave.poll(t_ns)
        return out

    def next_deadline_ns(self) -> int:
        """When `advance` has something to do next (the next sample, or a heartbeat / event timer before it)."""
        due = [self.sample_ns(self.driver.seq + 1)]
        due += [d for d in (a.slave.next_deadline_ns() for a in self.axes) if d is not None]
        return min(due)

    def note_bus_error(self, t_ns: int) -> list[Frame]:
        for a in self.axes:
            a.note_bus_error()
        return self._collect(t_ns)

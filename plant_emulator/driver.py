"""Emulated SEA driver firmware for one limb (one CAN node): state machine, watchdog, e-stop, plant integration.

Pure logic, no I/O: the node loop (`sea_hil.plant_emulator.node`) feeds it decoded frames and ticks. States:
INIT (powered, zero voltage) -> RUNNING on the first voltage command; RUNNING -> FAULT (WATCHDOG) when no command
arrived for `watchdog_timeout_s`; RUNNING -> FAULT (POSITION_LIMIT, VELOCITY_LIMIT and/or FORCE_LIMIT) when an
integrated sample leaves the soft limits (`soft_limits.DriveLimits`, zero voltage from that sample on); any state ->
ESTOP on an e-stop frame (latched). Only CLEAR_ERRORS leaves FAULT or ESTOP (back to INIT; a sample still outside a
limit faults the drive again as soon as a command makes it RUNNING). In FAULT, ESTOP and INIT the voltage is zero.

A voltage change takes effect when the frame arrives, as on a real drive: in real time the node sets
`period_start_ns` (monotonic time of the sample the current period starts from, i.e. when its feedback was sent) and
`step` integrates the period piecewise, the old voltage up to each change's arrival offset. With `period_start_ns`
None (lockstep, unit tests) a change acts from the start of the period: the computation takes no simulated time.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from sea_hil.dynamics import State, deflections, initial_state, saturate
from sea_hil.mechanics import LimbParams
from sea_hil.plant_emulator.integrator import Disturbance, advance
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.can_frames import (
    ClearErrors,
    DeflectionSetpoint,
    DriverState,
    ErrorFlags,
    EStop,
    Feedback,
    Heartbeat,
    VoltageCmd,
)

U16 = 0xFFFF


@dataclass
class DriverCounters:
    rejected_frames: int = 0
    ignored_commands: int = 0
    overruns: int = 0
    commands: int = 0
    watchdog_trips: int = 0
    limit_trips: int = 0
    heartbeat_seq: int = 0


@dataclass
class DriverCore:
    node_id: int
    params: LimbParams
    period_ns: int
    watchdog_ns: int
    substeps: int
    x: State
    disturbance: Disturbance
    limits: DriveLimits = DriveLimits()
    state: DriverState = DriverState.INIT
    flags: ErrorFlags = ErrorFlags(0)
    voltage_v: tuple[float, float] = (0.0, 0.0)
    last_cmd_ns: int = 0
    seq: int = 0          # samples integrated so far
    counters: DriverCounters = field(default_factory=DriverCounters)
    period_start_ns: int | None = None
    _u_start: tuple[float, float] = (0.0, 0.0)                                  # voltage at the period start
    _changes: list[tuple[int, tuple[float, float]]] = field(default_factory=list)  # (offset ns, voltage) this period

    @classmethod
    def create(cls, node_id: int, params: LimbParams, period_s: float, watchdog_s: float, substeps: int,
               theta0_rad: tuple[float, float], disturbance: Disturbance,
               limits: DriveLimits = DriveLimits()) -> DriverCore:
        x0 = initial_state(theta0_rad[0], theta0_rad[1], 0.0, 0.0, params)
        return cls(node_id, params, int(round(period_s * 1e9)), int(round(watchdog_s * 1e9)), substeps, x0,
                   disturbance, limits)

    @property
    def sample_t_ns(self) -> int:
        return self.seq * self.period_ns

    def reject(self) -> None:
        self.counters.rejected_frames += 1
        self.flags |= ErrorFlags.BAD_FRAME

    def handle(self, frame: object, now_ns: int) -> bool:
        """Apply one decoded frame addressed to this node; False if it is not a command the driver accepts."""
        if isinstance(frame, VoltageCmd):
            if self.state in (DriverState.FAULT, DriverState.ESTOP):
                self.counters.ignored_commands += 1
                return True
            limit = self.params.voltage_limit
            u = (saturate(frame.voltage_v[0], limit), saturate(frame.voltage_v[1], limit))
            if u != tuple(frame.voltage_v):
                self.flags |= ErrorFlags.SATURATED
            self._set_voltage(u, now_ns)
            self.state = DriverState.RUNNING
            self.last_cmd_ns = now_ns
            self.counters.commands += 1
            return True
        if isinstance(frame, EStop):
            self.state = DriverState.ESTOP
            self.flags |= ErrorFlags.ESTOP
            self._set_voltage((0.0, 0.0), now_ns)
            return True
        if isinstance(frame, ClearErrors):
            if self.state in (DriverState.FAULT, DriverState.ESTOP):
                self.state = DriverState.INIT
            self.flags = ErrorFlags(0)
            self.counters.rejected_frames = self.counters.overruns = 0  # DBC: counted since the last CLEAR_ERRORS
            self._set_voltage((0.0, 0.0), now_ns)
            return True
        if isinstance(frame, DeflectionSetpoint):
            # The inner loop runs on the edge in this firmware; the frame is defined for drives that host it.
            self.counters.ignored_commands += 1
            return False
        return False

    def note_overruns(self, missed: int) -> None:
        """The node's schedule missed `missed` feedback deadlines."""
        self.counters.overruns += missed
        self.flags |= ErrorFlags.OVERRUN

    def check_watchdog(self, now_ns: int) -> None:
        if self.state is DriverState.RUNNING and now_ns - self.last_cmd_ns > self.watchdog_ns:
            self.state = DriverState.FAULT
            self.flags |= ErrorFlags.WATCHDOG
            self._set_voltage((0.0, 0.0), now_ns)
            self.counters.watchdog_trips += 1

    def _set_voltage(self, u: tuple[float, float], now_ns: int) -> None:
        """The motor voltage becomes u at `now_ns` (its offset in the period; see the module docstring)."""
        self.voltage_v = u
        start = self.period_start_ns
        offset = 0 if start is None else min(max(now_ns - start, 0), self.period_ns)
        self._changes.append((offset, u))

    def step(self) -> Feedback:
        """Integrate one period (voltage held between the changes that arrived in it) and return the feedback of the
        new sample. Without changes inside the period this is one `advance` over the whole period. A driver node
        with several limbs runs `segments` of them all in one compiled call instead (`plant_emulator.batch`)."""
        x = self.x
        for t_s, dt_s, n, u in self.segments():
            x = advance(t_s, x, u, dt_s, n, self.params, self.disturbance)
        return self.finish_period(x)

    def segments(self) -> list[tuple[float, float, int, tuple[float, float]]]:
        """The period's pieces of constant voltage, in order: (start time s, length s, RK4 sub-steps, voltage)."""
        t_s = self.seq * self.period_ns * 1e-9
        out, start, u = [], 0, self._u_start
        for offset, new_u in (*self._changes, (self.period_ns, self.voltage_v)):
            if offset > start:
                n = max(1, -(-self.substeps * (offset - start) // self.period_ns))   # ceil: sub-steps no longer
                out.append((t_s + start * 1e-9, (offset - start) * 1e-9, n, u))
                start = offset
            u = new_u
        return out

    def finish_period(self, x: State, delta_m: tuple[float, float] | None = None) -> Feedback:
        """The period is integrated to `x` (spring deflections `delta_m` of x when the caller has them): the new
        sample, its feedback (and the soft-limit check)."""
        self.x = x
        self._u_start, self._changes = self.voltage_v, []
        self.seq += 1
        fb = self.feedback(delta_m)
        if self.state is DriverState.RUNNING:
            self._check_limits(fb)
        return fb

    def _check_limits(self, fb: Feedback) -> None:
        """Fault on a sample outside the soft limits: 0 V from this sample on (the start of the next period)."""
        violated = self.limits.violations(fb.theta_rad, fb.omega_rad_s, fb.delta_m, self.params)
        if violated:
            self.state = DriverState.FAULT
            self.flags |= violated
            self.voltage_v = self._u_start = (0.0, 0.0)
            self.counters.limit_trips += 1

    def feedback(self, delta_m: tuple[float, float] | None = None) -> Feedback:
        x = self.x
        d1, d2 = deflections(x, self.params)[:2] if delta_m is None else delta_m
        t_us = (self.sample_t_ns // 1000) & U16
        return Feedback(self.node_id, self.seq & 0xFF, t_us, (x[0], x[1]), (x[2], x[3]), (d1, d2), (x[6], x[7]))

    def heartbeat(self) -> Heartbeat:
        c = self.counters
        c.heartbeat_seq = (c.heartbeat_seq + 1) & 0xFF
        return Heartbeat(self.node_id, self.state, self.flags, min(c.rejected_frames, U16), min(c.overruns, U16),
                         c.heartbeat_seq)

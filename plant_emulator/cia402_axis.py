"""The CiA 402 application of one SEA (one CANopen node): the drive state machine (controlword 0x6040 ->
statusword 0x6041, CiA 402 figure 13), modes of operation (0x6060 / 0x6061 / 0x6502: cyclic synchronous torque 10
and the manufacturer voltage mode -1), the motor voltage it commands, its faults (EMCY 0x603F codes) and the actual
values of the latest plant sample. Pure: the limb core (`cia402_drive.Cia402Limb`) feeds it samples and time.

Torque loop (docs/cia402.md): the paper's plant (Eq. 6) has a voltage input and no motor constants, so the drive's
current loop is modelled as ideal and static: torque demand T (per mille of 0x6076, clipped to +-0x6072) gives the
motor voltage U = T / 1000 * voltage_limit_v. 0x6077 reports the applied demand (the same map back from the applied
voltage); the torque the spring puts on the joint, -k Delta dL/dtheta, is 0x2103.

Faults reuse the driver firmware's soft-limit logic (`soft_limits.DriveLimits`, restricted to this joint, checked
on every sample while OPERATION ENABLED, as `DriverCore` does while RUNNING) and its command watchdog rule (no
target for longer than 0x2012 ms while a target is followed). The watchdog is armed by the first target written
after OPERATION ENABLED (CiA 301's RPDO deadline monitoring starts with the first reception; `DriverCore`'s arms as
its first command takes it to RUNNING): a drive enabled before its master streams targets does not trip. A fault: FAULT REACTION ACTIVE (0 V from that
instant) until the next sample, then FAULT; fault reset = controlword bit 7 rising edge -> SWITCH ON DISABLED.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from sea_hil.mechanics import LimbParams, sea_geometry
from sea_hil.plant_emulator.canopen_slave import RANGE, CanopenSlave, Frame
from sea_hil.plant_emulator.soft_limits import INF, DriveLimits
from sea_hil.protocol.can_frames import ErrorFlags, Feedback
from sea_hil.protocol.cia402_od import EMCY_CODES, EMCY_COMM_LOSS, MODE_CST, MODE_VOLTAGE, MODES, OPERATIONAL

GENERIC, VOLTAGE, COMMUNICATION, PROFILE = 0x01, 0x04, 0x10, 0x20


class State(IntEnum):
    NOT_READY = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


STATUS = {State.NOT_READY: 0x0000, State.SWITCH_ON_DISABLED: 0x0040, State.READY_TO_SWITCH_ON: 0x0021,
          State.SWITCHED_ON: 0x0033, State.OPERATION_ENABLED: 0x0037, State.QUICK_STOP_ACTIVE: 0x0017,
          State.FAULT_REACTION_ACTIVE: 0x001F, State.FAULT: 0x0008}   # bit 4 voltage enabled once switched on
REMOTE, WARNING, FOLLOWS = 0x0200, 0x0080, 0x1000


_HIGHEST = {bits: (1 << (bits - 1)) - 1 for bits in (8, 16, 32)}


def _clip(v: float, bits: int) -> int:
    """Round to a signed integer of `bits`, saturating (a non-finite value reads as 0: `round` refuses it)."""
    try:
        r = round(v)
    except (OverflowError, ValueError):
        return 0
    hi = _HIGHEST[bits]
    return -hi - 1 if r < -hi - 1 else hi if r > hi else r


@dataclass
class Cia402Axis:
    joint: int                      # 0 hip, 1 knee (the plant state's index)
    params: LimbParams
    slave: CanopenSlave = field(init=False)
    state: State = State.NOT_READY
    voltage_v: float = 0.0          # motor voltage commanded now
    last_target_ns: int | None = None   # the newest target written since OPERATION ENABLED (None: none yet)
    warnings: ErrorFlags = ErrorFlags(0)
    fault_flags: ErrorFlags = ErrorFlags(0)
    pending: list[Frame] = field(default_factory=list)   # EMCYs raised inside a write (sent by the limb core)
    limit_trips: int = 0
    watchdog_trips: int = 0
    _last_cw: int = 0               # the previous controlword (fault reset acts on bit 7's rising edge)

    # ---- SlaveApp -------------------------------------------------------------------------------------------------
    def check_write(self, index: int, subindex: int, value: int) -> int:
        v = self.slave.values
        if index == 0x6060 and value not in MODES:
            return RANGE
        if index == 0x607D and subindex in (1, 2):
            lo, hi = (value, int(v[(0x607D, 2)])) if subindex == 1 else (int(v[(0x607D, 1)]), value)
            return RANGE if lo >= hi else 0
        return 0

    def on_write(self, index: int, subindex: int, value: int, t_ns: int) -> None:
        v = self.slave.values
        if index == 0x6040:
            self._controlword(value, t_ns)
        elif index == 0x6060:
            v[(0x6061, 0)] = value
        elif index in (0x6071, 0x2000):
            if self._target_index() == index:
                self.last_target_ns = t_ns
        elif index == 0x2010:                            # also ends a bus-error warning
            self.slave.counters.rejected_frames = 0
            v[(0x2011, 0)] = 0
            self._warn(ErrorFlags.BUS_ERROR, False)
        self._update_output(t_ns)

    def on_nmt(self, old: int, new: int, t_ns: int) -> None:
        if old == OPERATIONAL and self.state is State.OPERATION_ENABLED:
            self._fault(EMCY_COMM_LOSS, ErrorFlags(0), t_ns)

    def on_reset(self) -> None:
        """Power-on or NMT reset node: the application restarts (values are back at their defaults)."""
        self.state, self.voltage_v, self._last_cw = State.SWITCH_ON_DISABLED, 0.0, 0
        self.warnings = self.fault_flags = ErrorFlags(0)
        self._publish_status()

    # ---- state machine --------------------------------------------------------------------------------------------
    def _controlword(self, cw: int, t_ns: int) -> None:
        s, old = self.state, self._last_cw
        self._last_cw = cw
        if s is State.FAULT:
            if cw & 0x80 and not old & 0x80:
                self.state, self.fault_flags = State.SWITCH_ON_DISABLED, ErrorFlags(0)
                self.slave.values[(0x603F, 0)] = 0
                self.pending += self.slave.emcy(0, self._register())
            self._publish_status()
            return
        if s in (State.FAULT_REACTION_ACTIVE, State.NOT_READY):
            return
        low = cw & 0x0F
        if not cw & 0x02:                                  # disable voltage: 7, 9, 10, 12
            self.state = State.SWITCH_ON_DISABLED
        elif not cw & 0x04:                                # quick stop (x01x): 11, or 7 / 10
            self.state = (State.QUICK_STOP_ACTIVE if s in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE)
                          else State.SWITCH_ON_DISABLED)
        elif low & 0x07 == 0x06:                           # shutdown: 2, 6, 8
            if s is not State.QUICK_STOP_ACTIVE:
                self.state = State.READY_TO_SWITCH_ON
        elif low == 0x07:                                  # switch on / disable operation: 3, 5
            if s in (State.READY_TO_SWITCH_ON, State.OPERATION_ENABLED):
                self.state = State.SWITCHED_ON
        elif low == 0x0F:                                  # enable operation: 4, 16 (3 + 4 from ready)
            if s in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.QUICK_STOP_ACTIVE):
                if self.state is not State.OPERATION_ENABLED:
                    self.last_target_ns = None       # the watchdog waits for the first target
                self.state = State.OPERATION_ENABLED
        self._publish_status()

    def _fault(self, code: int, flags: ErrorFlags, t_ns: int) -> None:
        self.state, self.fault_flags = State.FAULT_REACTION_ACTIVE, flags
        self.slave.values[(0x603F, 0)] = code
        self.voltage_v = 0.0
        self.pending += self.slave.emcy(code, self._register(code), int(flags).to_bytes(2, "little") + b"\0" * 3)
        self._publish_status()

    def _register(self, code: int | None = None) -> int:
        code = int(self.slave.values[(0x603F, 0)]) if code is None else code
        reg = (PROFILE if code >> 12 == 8 and code not in (0x8250, 0x8130, 0x8110) else 0)
        reg |= COMMUNICATION if code in (0x8250, 0x8130) or self.warnings & ErrorFlags.BUS_ERROR else 0
        reg |= VOLTAGE if self.warnings & ErrorFlags.SATURATED else 0
        return reg | (GENERIC if reg or code else 0)

    def _publish_status(self) -> None:
        sw = STATUS[self.state] | REMOTE | (WARNING if self.warnings else 0)
        if self.state is State.OPERATION_ENABLED and self._target_index() is not None:
            sw |= FOLLOWS
        self.slave.values[(0x6041, 0)] = sw

    def _target_index(self) -> int | None:
        mode = int(self.slave.values[(0x6061, 0)])
        return 0x6071 if mode == MODE_CST else 0x2000 if mode == MODE_VOLTAGE else None

    # ---- output, samples ------------------------------------------------------------------------------------------
    def _update_output(self, t_ns: int) -> None:
        v, limit = self.slave.values, self.params.voltage_limit
        u = 0.0
        if self.state is State.OPERATION_ENABLED:
            target = self._target_index()
            if target == 0x6071:
                t_max = int(v[(0x6072, 0)])
                u = max(-t_max, min(t_max, int(v[(0x6071, 0)]))) / 1000.0 * limit
            elif target == 0x2000:
                u = int(v[(0x2000, 0)]) / 1000.0
        saturated = abs(u) > limit
        self.voltage_v = max(-limit, min(limit, u))
        self._warn(ErrorFlags.SATURATED, saturated)
        self._publish_status()

    def _warn(self, flag: ErrorFlags, on: bool) -> None:
        if on == bool(self.warnings & flag):
            return
        self.warnings = self.warnings | flag if on else self.warnings & ~flag
        self.pending += self.slave.emcy(EMCY_CODES[flag] if on else 0, self._register())
        self._publish_status()

    def refresh_counters(self) -> None:
        self.slave.values[(0x2011, 0)] = min(self.slave.counters.rejected_frames, 2 ** 32 - 1)

    def note_bus_error(self) -> None:
        self._warn(ErrorFlags.BUS_ERROR, True)

    def on_sample(self, fb: Feedback, x_nut_m: float, t_ns: int) -> None:
        """A new plant sample at `t_ns`: actual values, fault reaction end, soft limits, watchdog."""
        j, v, p = self.joint, self.slave.values, self.params
        theta, omega, delta, rdot = fb.theta_rad[j], fb.omega_rad_s[j], fb.delta_m[j], fb.nut_vel_m_s[j]
        arm = sea_geometry(fb.theta_rad[0], fb.theta_rad[1], p)[2 + j]
        v[(0x6064, 0)], v[(0x606C, 0)] = _clip(theta * 1e6, 32), _clip(omega * 1e6, 32)
        v[(0x2100, 0)], v[(0x2101, 0)] = _clip(delta * 1e9, 32), _clip(rdot * 1e9, 32)
        v[(0x2102, 0)] = _clip(x_nut_m * 1e9, 32)
        v[(0x2103, 0)] = _clip(-(p.k1, p.k2)[j] * delta * arm * 1e3, 32)
        v[(0x2001, 0)] = _clip(self.voltage_v * 1e3, 16)
        v[(0x6077, 0)] = _clip(1000.0 * self.voltage_v / p.voltage_limit, 16)
        if self.state is State.FAULT_REACTION_ACTIVE:
            self.state = State.FAULT
            self._publish_status()
        if self.state is not State.OPERATION_ENABLED:
            return
        flags = self.limits().violations(fb.theta_rad, fb.omega_rad_s, fb.delta_m, p)
        if flags:
            self.limit_trips += 1
            first = next(f for f in (ErrorFlags.POSITION_LIMIT, ErrorFlags.VELOCITY_LIMIT, ErrorFlags.FORCE_LIMIT)
                         if flags & f)
            self._fault(EMCY_CODES[first], flags, t_ns)
            return
        watchdog_ns = int(v[(0x2012, 0)]) * 1_000_000
        if watchdog_ns and self._target_index() is not None and self.last_target_ns is not None \
                and t_ns - self.last_target_ns > watchdog_ns:
            self.watchdog_trips += 1
            self._fault(EMCY_CODES[ErrorFlags.WATCHDOG], ErrorFlags.WATCHDOG, t_ns)

    def limits(self) -> DriveLimits:
        """This joint's soft limits (0x607D, 0x607F, 0x2110) as the firmware's `DriveLimits`, the other joint
        unlimited."""
        v, j = self.slave.values, self.joint
        lo, hi = [-INF, -INF], [INF, INF]
        vel, force = [INF, INF], [INF, INF]
        lo[j], hi[j] = int(v[(0x607D, 1)]) * 1e-6, int(v[(0x607D, 2)]) * 1e-6
        vel[j], force[j] = int(v[(0x607F, 0)]) * 1e-6, int(v[(0x2110, 0)]) * 1e-3
        return DriveLimits((lo[0], lo[1]), (hi[0], hi[1]), (vel[0], vel[1]), (force[0], force[1]))

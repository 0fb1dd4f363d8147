"""The edge's command path: from one feedback sample and the held setpoint (or tunnelled voltage) to the
VOLTAGE_CMD on CAN; clears a driver fault when setpoints are fresh again (as the clock allows)."""
from __future__ import annotations

import logging
from typing import Any

import can

from sea_hil.controller.edge_downlink import SETPOINT_BYTES
from sea_hil.controller.inner import InnerLoop
from sea_hil.errors import BusError
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import LIMIT_FLAGS, ClearErrors, DriverState, ErrorFlags, Feedback, VoltageCmd
from sea_hil.protocol.canbus import CanHandle, send_with_retry
from sea_hil.protocol.payloads import SetpointPayload

log = logging.getLogger("sea_hil.edge")


class CommandPath:
    def __init__(self, bus: CanHandle, codec: SeaCodec, node_id: int, inner: InnerLoop, inner_mode: str,
                 send_retries: int, counters: Any) -> None:
        self.bus, self.codec, self.node_id = bus, codec, node_id
        self.inner, self.inner_mode = inner, inner_mode
        self.send_retries = send_retries
        self.counters = counters
        self.voltage: tuple[float, float] | None = None    # the newest tunnelled voltage (inner = remote)
        self.driver_state = DriverState.INIT
        self.driver_flags = ErrorFlags(0)         # the driver's error flags from its latest HEARTBEAT
        self.last_cmd: can.Message | None = None

    def send(self, msg: can.Message) -> None:
        try:
            send_with_retry(self.bus, msg, self.send_retries, 0.0002)
        except BusError as err:
            self.counters.bus_errors += 1
            log.warning("%s", err)

    def apply(self, p: object) -> None:
        """Hold an applied setpoint (inner loop) or tunnelled voltage."""
        if isinstance(p, SetpointPayload):
            self.inner.hold(p.deflection_m, p.sliding)
            self.counters.setpoints += 1
            self.counters.setpoint_bytes += SETPOINT_BYTES
        else:
            self.voltage = p.voltage_v   # type: ignore[attr-defined]
            self.counters.voltages += 1

    def step_only(self, fb: Feedback) -> None:
        """Run the inner loop on `fb` (observer, resume ramp) without sending: a sample too late to answer."""
        if self.inner_mode != "remote":
            self.inner.voltage((*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s))

    def answer(self, fb: Feedback, command: bool, clear: bool) -> bool:
        """Compute and send the VOLTAGE_CMD answering `fb` (False: not commanding). `command`/`clear` come from the
        clock's gate on setpoint freshness."""
        if not command:
            return False     # stop commanding: the driver watchdog takes it to its safe state
        # a watchdog fault is cleared when setpoints come back; a soft-limit fault (LIMIT_FLAGS) is left to the operator
        if clear and self.driver_state is DriverState.FAULT and not self.driver_flags & LIMIT_FLAGS:
            self.send(self.codec.encode(ClearErrors(self.node_id)))
            self.counters.clear_errors_sent += 1
            self.driver_state = DriverState.INIT
        if self.inner_mode == "remote":
            u = self.voltage if self.voltage is not None else (0.0, 0.0)
        else:
            m = (*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s)
            u = self.inner.voltage(m)
        self.last_cmd = self.codec.encode(VoltageCmd(self.node_id, u, fb.seq), saturate=True)
        self.send(self.last_cmd)
        return True

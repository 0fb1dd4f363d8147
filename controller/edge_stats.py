"""The edge node's counters and the small pure helpers of its statistics (`controller/edge.py`)."""
from __future__ import annotations

from dataclasses import dataclass, field

from sea_hil.stats.histogram import LogHistogram


@dataclass
class EdgeCounters:
    feedback: int = 0
    rejected_frames: int = 0
    rejected_samples: int = 0            # feedback whose sample time does not advance (stale, clock reset)
    states_sent: int = 0
    state_bytes: int = 0
    setpoints: int = 0
    setpoint_bytes: int = 0
    voltages: int = 0
    stale_setpoints: int = 0
    unexpected_payloads: int = 0
    controller_restarts: int = 0
    bus_errors: int = 0
    clear_errors_sent: int = 0
    lockstep_resends: int = 0            # re-publishes after the controller first answered
    lockstep_startup_resends: int = 0    # re-publishes before its first ACK (controller starting)
    commands_sent: int = 0               # VOLTAGE_CMDs answering feedback samples
    arrival_commands: int = 0            # real time: extra VOLTAGE_CMDs sent when a setpoint arrived
    latency: LogHistogram = field(default_factory=LogHistogram)      # wall clock: state published -> answer arrived
    apply_latency: LogHistogram = field(default_factory=LogHistogram)  # wall clock: state published -> answer applied
    sim_latency: LogHistogram = field(default_factory=LogHistogram)  # sample time: state sampled -> applied
    loop: LogHistogram = field(default_factory=LogHistogram)         # feedback received -> VOLTAGE_CMD sent
    loop_overruns: int = 0                                           # loop time > one feedback period
    uplink_out_of_order: int = 0                                     # lockstep: released after a newer state


def rx_monotonic_ns(frame_timestamp_s: float, mono_now_ns: int, wall_now_ns: int, *,
                    max_age_ns: int = 10**10) -> int:
    """The monotonic time at which a frame stamped `frame_timestamp_s` (python-can: wall clock, set by the sender on
    the virtual bus, by the kernel on SocketCAN) arrived, so queueing and wake-up count in the loop time; `mono_now_ns`
    when the stamp is missing or implausible (in the future or older than `max_age_ns`)."""
    age_ns = wall_now_ns - int(frame_timestamp_s * 1e9)
    return mono_now_ns - age_ns if 0 <= age_ns <= max_age_ns else mono_now_ns


def percentiles_us(name: str, h: LogHistogram, keys: tuple[str, ...]) -> dict[str, float]:
    """`{name}_us_{key}` in microseconds (-1 when empty) for keys of `LogHistogram.to_dict` (min, p50, p99, max)."""
    d = h.to_dict()
    return {f"{name}_us_{k}": float(d[k]) * 1e6 if d[k] is not None else -1.0 for k in keys}

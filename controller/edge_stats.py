"""The edge node's counters, its stats fields (`edge_stats`) and the small pure helpers of its statistics
(`controller/edge.py`)."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import can

from sea_hil.protocol.payload_fields import RejectReason
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
    resumes: int = 0                     # bumpless resumes after a stop / the drive's safe state (InnerLoop.resume)
    late_samples: int = 0                # real time: samples not answered, received > max_sample_age_s before
    late_setpoints: int = 0              # answers to states sampled > max_answer_age_s before: dropped


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
    return {f"{name}_us_{k}": float(v) * 1e6 if (v := d[k]) is not None else -1.0 for k in keys}


def edge_stats(edge: Any) -> dict[str, float]:
    """The flat counters of an `EdgeNode` (the fields of its stats record; keys read by the session summary)."""
    c, intake, pub = edge.counters, edge.intake, edge.publisher
    lat = c.latency.to_dict()
    up, down = pub.uplink.link.counters(), intake.downlink.counters()
    sp_seq = intake.sp_seq
    out: dict[str, float] = {
        "node_id": edge.node_id, "feedback_samples": c.feedback, "rejected_frames": c.rejected_frames,
        "rejected_samples": c.rejected_samples,
        "uplink_msgs": c.states_sent, "uplink_bytes": c.state_bytes, "downlink_applied": c.setpoints,
        "voltage_msgs_applied": c.voltages, "stale_setpoints": c.stale_setpoints,
        "clear_errors_sent": c.clear_errors_sent, "lockstep_resends": c.lockstep_resends,
        "lockstep_startup_resends": c.lockstep_startup_resends,
        "commands_sent": c.commands_sent, "arrival_commands": c.arrival_commands,
        "payload_rejected": edge.payloads.as_dict()["rejected_total"],
        **{f"payload_rejected_{r.value}": edge.payloads.rejected[r.value] for r in RejectReason},
        "unexpected_payloads": c.unexpected_payloads, "controller_restarts": c.controller_restarts,
        "setpoints_out_of_envelope": edge.envelope.rejected,
        "bus_errors": c.bus_errors, "late_samples": c.late_samples, "late_setpoints": c.late_setpoints,
        "uplink_dropped": up.dropped, "downlink_dropped": down.dropped, "saturated_steps": edge.inner.saturated_steps,
        "seq_lost": sp_seq.lost, "seq_reordered": sp_seq.reordered, "seq_duplicates": sp_seq.duplicates,
        **intake.epoch.as_dict(),
        "latency_count": lat["count"],
        "uplink_submitted": up.submitted, "uplink_mean_added_delay_s": up.mean_added_delay_s,
        "downlink_submitted": down.submitted, "downlink_mean_added_delay_s": down.mean_added_delay_s,
    }
    for k in ("p50", "p90", "p99", "max", "min", "mean"):
        v = lat.get(k)
        out[f"latency_{k}_us"] = (v * 1e6) if v is not None else -1.0
    out.update(percentiles_us("sim_latency", c.sim_latency, ("min", "p50", "max")),
               **percentiles_us("apply_latency", c.apply_latency, ("p50", "p99", "max")),
               **percentiles_us("loop", c.loop, ("p50", "p99", "max")),
               loop_count=c.loop.count, loop_overruns=c.loop_overruns, uplink_out_of_order=c.uplink_out_of_order,
               uplink_pending=pub.uplink.pending)
    timing = getattr(edge.bus, "timing_stats", None)   # [can] emulate_bitrate: queueing delay per CAN id
    if timing is not None:
        out.update(timing())
    if edge.events is not None:     # the trigger at the edge (issue 16); absent on the paper's path
        out.update(edge.events.stats(), **edge.events.fallback_stats())
    return out


def receive_stamped(bus: Any, stop_event: Any, on_error: Callable[[Exception], None],
                    timeout_s: float = 0.05) -> tuple[Any, int] | None:
    """One frame from `bus` and its monotonic arrival time (`rx_monotonic_ns`), or None after `timeout_s` without
    one. A receive error (e.g. the interface went down) goes to `on_error` (count, log), then waits `timeout_s` on
    `stop_event` and returns None: the node keeps running."""
    try:
        msg = bus.recv(timeout=timeout_s)
    except (can.CanError, OSError) as err:
        on_error(err)
        stop_event.wait(timeout_s)
        return None
    if msg is None:
        return None
    return msg, rx_monotonic_ns(msg.timestamp, time.monotonic_ns(), time.time_ns())

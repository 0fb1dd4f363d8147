"""The bus-timing model (`[can] emulate_bitrate`): when each frame would be on the wire of a real CAN bus.

vcan and python-can's `virtual` bus deliver a frame the moment it is sent, however loaded the bus is. `BusArbiter`
is a pure discrete-event model of one bus: a frame becomes ready when it is sent; whenever the bus is idle, the
ready frame with the highest priority (lowest identifier; an 11-bit id beats the 29-bit ids sharing its top 11 bits;
equal ids in send order) wins arbitration and occupies the bus for its transmission time (`frame_time_ns`: classic
CAN, or CAN FD with the data phase at the data rate, worst-case stuffing); it is delivered when its transmission
ends. A frame in transmission is never pre-empted. So bus load shows up as queueing delay (start - ready) and
latency (end - ready) per id, as on a real bus; `stats()` / `flat_stats()` report them. All times are integer
nanoseconds of whatever clock the caller uses (monotonic in real time, simulated time in lockstep), so the model is
deterministic. The clocked handles that put sessions on it are in `sea_hil.protocol.timed_bus`.

`planned_load_pct` is the load a configuration puts on a bus before anything is sent (feedback + voltage frames per
sample, heartbeats), for the session's start-up warning.
"""
from __future__ import annotations

import heapq
import itertools
import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import can

from sea_hil.config.comms import CanConfig
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Feedback, Heartbeat, VoltageCmd
from sea_hil.stats.can_bits import NS_PER_S, frame_time_ns
from sea_hil.stats.histogram import LogHistogram

log = logging.getLogger("sea_hil.can")


@dataclass(frozen=True)
class BusRates:
    """The bit rates of one bus: nominal (arbitration, classic CAN) and CAN FD data phase."""
    bitrate_bps: int = 1_000_000
    data_bitrate_bps: int = 5_000_000

    @classmethod
    def of(cls, can_cfg: Any) -> BusRates:
        return cls(int(can_cfg.bitrate_bps), int(can_cfg.data_bitrate_bps))

    def frame_ns(self, msg: can.Message) -> int:
        """Transmission time of `msg` (worst-case stuffing, interframe space included)."""
        return frame_time_ns(msg.dlc, extended=bool(msg.is_extended_id), fd=bool(msg.is_fd),
                             bitrate_switch=bool(msg.bitrate_switch), bitrate_bps=self.bitrate_bps,
                             data_bitrate_bps=self.data_bitrate_bps)


def priority(msg: can.Message) -> tuple[int, int]:
    """Arbitration order key (smaller wins): the 11 base id bits first, then standard before extended, then the 18
    extension bits."""
    if msg.is_extended_id:
        return (msg.arbitration_id >> 18, 1 << 18 | msg.arbitration_id & 0x3FFFF)
    return (msg.arbitration_id, 0)


class Transmission(NamedTuple):
    """One frame on the wire: ready (sent) -> start (won arbitration) -> end (delivered), nanoseconds."""
    ready_ns: int
    start_ns: int
    end_ns: int
    msg: can.Message
    token: Any


@dataclass
class _IdStats:
    frames: int = 0
    queue: LogHistogram = field(default_factory=lambda: LogHistogram(lowest=1e-9, highest=10.0))
    latency: LogHistogram = field(default_factory=lambda: LogHistogram(lowest=1e-9, highest=10.0))


class BusArbiter:
    """Pure model of one bus (see the module docstring): `submit` frames as they are sent, `next_transmission` the
    next one on the wire once everything sent up to its start is known."""

    def __init__(self, rates: BusRates) -> None:
        self.rates = rates
        self.busy_until_ns = 0
        self._pending: list[tuple[int, int, tuple[int, int], can.Message, Any]] = []   # heap by ready time
        self._order = itertools.count()
        self._ids: dict[int, _IdStats] = {}
        self.busy_ns = 0
        self.frames = 0
        self.first_ready_ns: int | None = None

    @property
    def pending(self) -> int:
        return len(self._pending)

    def submit(self, ready_ns: int, msg: can.Message, token: Any = None) -> None:
        if self.first_ready_ns is None:
            self.first_ready_ns = int(ready_ns)
        heapq.heappush(self._pending, (int(ready_ns), next(self._order), priority(msg), msg, token))

    def next_start_ns(self) -> int | None:
        """When the bus takes its next frame (None: nothing pending)."""
        return max(self.busy_until_ns, self._pending[0][0]) if self._pending else None

    def next_transmission(self, known_until_ns: float = float("inf")) -> Transmission | None:
        """The next frame on the wire, or None when nothing is pending or its start lies after `known_until_ns`
        (frames sent before the start could still join the arbitration)."""
        start = self.next_start_ns()
        if start is None or start > known_until_ns:
            return None
        contenders = [e for e in self._pending if e[0] <= start]
        win = min(contenders, key=lambda e: (e[2], e[1]))
        self._pending.remove(win)
        heapq.heapify(self._pending)
        ready, _, _, msg, token = win
        end = start + self.rates.frame_ns(msg)
        self.busy_until_ns = end
        self.busy_ns += end - start
        self.frames += 1
        s = self._ids.setdefault(msg.arbitration_id, _IdStats())
        s.frames += 1
        s.queue.record(max((start - ready) * 1e-9, 1e-9))
        s.latency.record(max((end - ready) * 1e-9, 1e-9))
        return Transmission(ready, start, end, msg, token)

    def stats(self) -> dict[str, Any]:
        """Per-id frames, queueing delay and latency (microseconds: p50, p99, max), and the bus load (busy time over
        first frame ready .. last frame delivered)."""
        def us(h: LogHistogram) -> dict[str, float]:   # values are recorded + 1 ns (a log histogram has no 0)
            d = h.to_dict()
            return {k: -1.0 if (v := d[k]) is None else 0.0 if v < 1e-8 else round(float(v) * 1e6, 3)
                    for k in ("p50", "p99", "max")}
        span = self.busy_until_ns - (self.first_ready_ns or 0)
        return {"bitrate_bps": self.rates.bitrate_bps, "data_bitrate_bps": self.rates.data_bitrate_bps,
                "frames": self.frames, "load_pct": 100.0 * self.busy_ns / span if span else 0.0,
                "per_id": [{"can_id": k, "frames": s.frames, "queue_us": us(s.queue), "latency_us": us(s.latency)}
                           for k, s in sorted(self._ids.items())]}

    def flat_stats(self) -> dict[str, float]:
        """`stats()` as flat `/stats` fields: `can_<id hex>_queue_us_<p50|p99|max>`, `..._latency_us_...`."""
        out: dict[str, float] = {"can_frames": self.frames}
        for e in self.stats()["per_id"]:
            key = f"can_{e['can_id']:03x}"
            out[f"{key}_frames"] = e["frames"]
            for what in ("queue_us", "latency_us"):
                out.update({f"{key}_{what}_{k}": v for k, v in e[what].items()})
        return out


def planned_load_pct(can_cfg: CanConfig, node_ids: Iterable[int]) -> float:
    """Bus load (%) the configured profile plans for `node_ids` on one bus: per node and sample its feedback and
    its voltage frame at `feedback_rate_hz`, its heartbeat at `heartbeat_rate_hz` (worst-case stuffing)."""
    codec, rates, z = SeaCodec.for_bus(can_cfg), BusRates.of(can_cfg), (0.0, 0.0)
    sample = codec.encode_feedback(Feedback(1, 0, 0, z, z, z, z)) + [codec.encode(VoltageCmd(1, z, 0))]
    per_node_ns = (sum(rates.frame_ns(m) for m in sample) * can_cfg.feedback_rate_hz
                   + rates.frame_ns(codec.encode(Heartbeat(1, DriverState.INIT, ErrorFlags(0), 0, 0, 0)))
                   * can_cfg.heartbeat_rate_hz)
    return 100.0 * per_node_ns * len(tuple(node_ids)) / NS_PER_S


def warn_if_overloaded(can_cfg: Any, node_ids: Iterable[int], spec: str) -> float:
    """Log a warning when the planned load of bus `spec` is above `[can] bus_load_warn_pct`; -> the planned load."""
    nodes = tuple(node_ids)
    pct = planned_load_pct(can_cfg, nodes)
    if pct > can_cfg.bus_load_warn_pct:
        profile = (f"CAN FD {can_cfg.bitrate_bps / 1e6:g}/{can_cfg.data_bitrate_bps / 1e6:g} Mbit/s" if can_cfg.fd
                   else f"classic CAN {can_cfg.bitrate_bps / 1e6:g} Mbit/s")
        log.warning("CAN bus %s is planned at %.1f %% load (%d node(s), %s, %g Hz feedback), above %g %%: frames "
                    "will queue%s", spec, pct, len(nodes), profile, can_cfg.feedback_rate_hz,
                    can_cfg.bus_load_warn_pct, "" if can_cfg.fd else "; [can] fd = true carries more limbs per bus")
    return pct

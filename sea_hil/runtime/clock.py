"""Clocks: what paces a node and how it meets its peers. A node asks its clock for its part (`plant(node)`,
`edge(node)`, `controller(node)`) once, when it is built; the node's logic never asks which clock it has.

- `RealTimeClock` (this module): the driver keeps a drift-free schedule of absolute deadlines; the edge applies a
  setpoint on arrival and stops commanding when setpoints stop (the driver's watchdog then acts); the controller
  takes the newest state only; stream restarts (a restarted controller or edge) are detected.
- `LockstepClock` (`sea_hil.runtime.lockstep`, the one module with all lockstep logic: ACKs, waits, re-sends):
  simulated time advances only when every node has handled the step; deterministic, as fast as possible.

`clock_for(lockstep)` (`sea_hil.runtime.lockstep`, beside the clock it may pick) is the one place the choice is made
from an option.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Protocol

import zenoh

from sea_hil.config.timing import TimingConfig
from sea_hil.protocol.keys import KEY_PAYLOADS
from sea_hil.protocol.payloads import AckPayload
from sea_hil.protocol.sequence import SeqVerdict
from sea_hil.protocol.zlatest import LatestSubscriber
from sea_hil.runtime.realtime import ThreadPolicy


class Pacer(Protocol):
    """The driver's schedule (`Clock.plant`): real-time deadlines, or one lockstep step per tick."""

    done: bool

    def start(self, duration_s: float | None) -> None: ...

    def tick(self) -> None: ...

    def on_command(self, frame: object, drv: Any) -> None:
        """A command the driver accepted (lockstep: the step's answer from that drive)."""


class EdgeSync(Protocol):
    """How the edge meets its peers (`Clock.edge`): when a setpoint applies, what a state is stamped with, whether
    the edge waits for the controller."""

    congestion_control: zenoh.CongestionControl
    lockstep: bool      # simulated time (the edge's final /stats says so: a recording's kind of run)

    def downlink_callback(self, channel: str) -> Callable[[zenoh.Sample], None]: ...

    def control_callback(self) -> Callable[[zenoh.Sample], None]: ...

    def on_ack(self, data: bytes) -> bool: ...

    def repeat_feedback(self, fb: Any) -> bool: ...

    def state_sent(self, at_ns: int, seq: int, data: bytes) -> None: ...

    def state_stamp(self, at_ns: int) -> int: ...

    def sync(self, now_ns: int) -> None: ...

    def drain(self) -> bool: ...

    def gate(self, fresh: bool) -> tuple[bool, bool]: ...

    def late(self, rx_ns: int) -> bool: ...

    def restart_possible(self, timed_out: bool) -> bool: ...


class StateSource(Protocol):
    """The controller's incoming states: the newest only (real time) or every one in order (lockstep).
    `superseded`: states a newer one replaced before the controller read them (real time; they arrived, so they are
    no loss on the way)."""

    @property
    def superseded(self) -> int: ...

    def recv(self, timeout_s: float) -> bytes | None: ...

    def close(self) -> None: ...


class ControllerSync(Protocol):
    """How the remote controller meets the edge (`Clock.controller`): its state source, re-answers, ACKs."""

    congestion_control: zenoh.CongestionControl

    def state_source(self, session: zenoh.Session, key: str) -> StateSource: ...

    def repeat_state(self, verdict: SeqVerdict, seq: int) -> bool: ...

    def answer_extra(self, state_seq: int, setpoint_seq: int, sent: bool) -> list[tuple[Any, bytes]]: ...

    def answered(self, seq: int, answer: list[tuple[Any, bytes]]) -> None: ...

    def arrival_ns(self, p: Any) -> int: ...

    def restart_possible(self, silent: bool) -> bool: ...

    def close(self) -> None: ...


class Clock(Protocol):
    """Factory of the per-node parts of one pacing scheme (`RealTimeClock`, `sea_hil.runtime.lockstep.LockstepClock`).
    """

    name: str

    def plant(self, node: Any) -> Pacer: ...

    def edge(self, node: Any) -> EdgeSync: ...

    def controller(self, node: Any) -> ControllerSync: ...


class RealTimeClock(Clock):
    name: str = "realtime"

    def plant(self, node: Any) -> RealTimePacer:
        return RealTimePacer(node)

    def edge(self, node: Any) -> RealTimeEdgeSync:
        return RealTimeEdgeSync(node)

    def controller(self, node: Any) -> RealTimeControllerSync:
        return RealTimeControllerSync(node)


class RealTimePacer:
    """The driver's real-time schedule: one tick per feedback period, one wake per tick (a sleep to the deadline;
    the frames that came meanwhile are handled then, each at its arrival time, so commands act from their arrival).
    Lateness of each tick is recorded; a tick later than one period is an overrun (the schedule skips ahead, never
    bunches up)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.done = False
        timing = getattr(getattr(node, "cfg", None), "timing", None) or TimingConfig()
        self.timing = timing
        self.policy = ThreadPolicy(timing, "driver")
        self.applied: dict[str, object] = {}

    def start(self, duration_s: float | None) -> None:
        """In the driver's thread: its `[timing]` policy (docs/timing.md), the compiled kernels, then the schedule."""
        n = self.node
        self.applied = self.policy.apply()
        n.on_loop_exit(self.policy.undo)
        n.prepare_kernels()
        self.start_ns = time.monotonic_ns()
        self.end_ns = None if duration_s is None else self.start_ns + int(duration_s * 1e9)
        for drv in n.drivers.values():
            drv.last_cmd_ns = self.start_ns
        n.publish_samples([(drv, drv.feedback()) for drv in n.drivers.values()])
        self.k, self.next_heartbeat_k, self.done = 0, n.heartbeat_every, False

    def tick(self) -> None:
        """One wake per tick: send the last tick's frames and sleep to the deadline at once (`PlantNode.wait_until`),
        handle the frames that arrived meanwhile (each at its arrival time), integrate every limb."""
        n = self.node
        self.k += 1
        deadline = self.start_ns + self.k * n.period_ns
        n.wait_until(deadline)
        now = time.monotonic_ns()
        n.take_pending(now)
        late = now - deadline
        n.lateness.record(max(late, 0) * 1e-9 + 1e-7)
        missed = late // n.period_ns if late > n.period_ns else 0
        n.stats.overruns += missed
        self.k += missed
        n.stats.ticks += 1
        for drv in n.drivers.values():
            if missed:
                drv.note_overruns(missed)
            drv.check_watchdog(now)
        heartbeat = self.k >= self.next_heartbeat_k   # skipped ticks must not skip the heartbeat
        n.publish_samples(n.step_drivers(), heartbeat)   # all limbs in one compiled step; sent by the next wait
        if heartbeat:
            self.policy.refresh()   # [timing] realtime_scope = "process": threads started since
            self.next_heartbeat_k = (self.k // n.heartbeat_every + 1) * n.heartbeat_every
        if self.end_ns is not None and now >= self.end_ns:
            self.done = True
            n.send_pending()

    def on_command(self, frame: object, drv: Any) -> None:
        """A command the driver accepted: nothing to wait for in real time."""


class RealTimeEdgeSync:
    """Edge in real time: setpoints/voltages are handled as they arrive (`EdgeNode.on_arrival`); nothing waits."""
    congestion_control = zenoh.CongestionControl.DROP   # a late control message is worth less than a fresh one
    lockstep = False

    def __init__(self, edge: Any) -> None:
        self.edge = edge

    def downlink_callback(self, channel: str) -> Callable[[zenoh.Sample], None]:
        """The subscriber callback of the edge's downlink key `channel` ("setpoint" | "voltage")."""
        on_arrival = self.edge.on_arrival
        return lambda s: on_arrival(s.payload.to_bytes(), time.monotonic_ns(), channel)

    def control_callback(self) -> Callable[[zenoh.Sample], None]:
        def on_control(s: zenoh.Sample) -> None:
            with self.edge.lock:
                self.on_ack(s.payload.to_bytes())
        return on_control

    def on_ack(self, data: bytes) -> bool:
        """A payload on the control key: an ACK means nothing in real time; anything else is counted, dropped."""
        return control_payload(self.edge.core, data) is not None

    def repeat_feedback(self, fb: Any) -> bool:
        return False

    def state_sent(self, at_ns: int, seq: int, data: bytes) -> None:
        pass

    def state_stamp(self, at_ns: int) -> int:
        """A state's header t_ns: the sender's monotonic clock at sending (the controller, on a synchronised clock,
        measures the uplink delay from it)."""
        return time.monotonic_ns()

    def sync(self, now_ns: int) -> None:
        pass

    def drain(self) -> bool:
        return False

    def gate(self, fresh: bool) -> tuple[bool, bool]:
        """(command at all, clear a driver fault): only with a fresh setpoint; a stale one lets the watchdog act."""
        return fresh, fresh

    def late(self, rx_ns: int) -> bool:
        """Is a feedback sample received at monotonic `rx_ns` too old to answer (`edge.max_sample_age_ns`; 0 or an
        unknown receive time: never)?"""
        max_ns = self.edge.core.max_sample_age_ns
        return max_ns > 0 and rx_ns > 0 and time.monotonic_ns() - rx_ns > max_ns

    def restart_possible(self, timed_out: bool) -> bool:
        return timed_out


def control_payload(core: Any, data: bytes) -> AckPayload | None:
    """Decode a control-key payload with the edge core's counters; a non-ACK is counted (`payload_rejected_key`)
    and dropped."""
    p = core.payloads.try_decode(data, KEY_PAYLOADS["control"])   # another type: rejected as KEY, counted
    return p if isinstance(p, AckPayload) else None


class RealTimeControllerSync:
    """Controller in real time: the newest state only (never a backlog), no ACKs."""
    congestion_control = zenoh.CongestionControl.DROP

    def __init__(self, ctrl: Any) -> None:
        self.ctrl = ctrl
        self.policy: ThreadPolicy | None = None

    def state_source(self, session: zenoh.Session, key: str) -> LatestStates:
        """The newest-state source; with `[timing] controller_priority` (set by `sea-hil run` for its controller
        children) this process's threads get SCHED_FIFO from here on: after the start-up (imports, Zenoh), never
        during it; undone by `close`."""
        timing = getattr(self.ctrl.cfg, "timing", None) or TimingConfig()
        if timing.controller_priority > 0:
            self.policy = ThreadPolicy(TimingConfig(realtime_priority=timing.controller_priority,
                                                    realtime_scope="process"), "controller")
            self.policy.apply()
        return LatestStates(LatestSubscriber(session, key))

    def repeat_state(self, verdict: Any, seq: int) -> bool:
        return False

    def answer_extra(self, state_seq: int, setpoint_seq: int, sent: bool) -> list[tuple[Any, bytes]]:
        return []

    def answered(self, seq: int, answer: list[tuple[Any, bytes]]) -> None:
        pass

    def arrival_ns(self, p: Any) -> int:
        """The state's arrival on the edge's sample clock: its sample time + its uplink delay, measured as now minus
        its header t_ns on synchronised monotonic clocks (one host: the same CLOCK_MONOTONIC; across hosts PTP or
        chrony), never negative."""
        return p.sample_t_ns + max(0, time.monotonic_ns() - p.t_ns)

    def restart_possible(self, silent: bool) -> bool:
        return silent

    def close(self) -> None:
        if self.policy is not None:
            self.policy.undo()


class LatestStates:
    def __init__(self, sub: LatestSubscriber) -> None:
        self.sub = sub

    @property
    def superseded(self) -> int:
        return self.sub.overwritten

    def recv(self, timeout_s: float) -> bytes | None:
        sample = self.sub.recv(timeout_s)
        return None if sample is None else sample.payload.to_bytes()

    def close(self) -> None:
        self.sub.close()

"""Several CAN buses as one handle for one thread: `MergedBus(routes)` receives from every bus and sends each frame
on the bus of its node id (`routes`: node id -> that node's handle on its bus; `can_id >> CMD_BITS` names the node).

Why (issue 17, docs/timing.md "Where the CPU goes"): classic CAN carries one limb per bus, so `--limbs 4` has four
buses, and a session with one driver thread, one edge thread and one recorder tap per bus runs 12 Python threads
that wake and hand the GIL to each other per frame. Merged, one driver thread integrates every limb in one batched
step, one edge thread serves every limb and one tap records every bus, whatever the number of buses. The frames
and their buses are the same: only the reading side is shared.

How: `FastVirtualBus` handles (the `virtual:` buses of one process) get one shared receive queue (each handle's
queue on its channel is replaced by it, so a frame sent on bus k still reaches only bus k's other handles); buses
with a file descriptor (socketcan, ipc, udp_multicast) are waited for together with `select`. Anything else (e.g. the
bus-timing model's `TimedBus`) cannot be merged: `can_merge` says so and the caller keeps one node per bus.
"""
from __future__ import annotations

import collections
import queue
import select
from collections.abc import Mapping, Sequence
from typing import Any

import can
from can.interfaces.virtual import channels_lock

from sea_hil.errors import BusError
from sea_hil.protocol.can_frames import CMD_BITS
from sea_hil.protocol.canbus import FastVirtualBus, send_all, take_queued, unbatch
from sea_hil.queues import timed_get


def _has_fileno(bus: Any) -> bool:
    try:
        bus.fileno()
    except (NotImplementedError, AttributeError, OSError, ValueError):
        return False
    return True


def _distinct(buses: Any) -> list[Any]:
    out: list[Any] = []
    for b in buses:
        if all(b is not o for o in out):
            out.append(b)
    return out


def can_merge(buses: Any) -> bool:
    """True if one `MergedBus` can read all of `buses`: all plain-queue `FastVirtualBus` handles without filters,
    or all with a file descriptor."""
    buses = list(buses)
    if all(type(b) is FastVirtualBus and isinstance(b.queue, queue.SimpleQueue) and not b._filters for b in buses):
        return True
    return all(not isinstance(b, FastVirtualBus) and _has_fileno(b) for b in buses)


class MergedBus:
    """One receiving handle over several buses (see the module docstring). `send` routes by node id; `recv` gives
    the next frame of any bus (frames of one bus keep their order). It owns none of the buses: the caller (the
    `SessionBuilder`) shuts them down."""

    simulated = False

    def __init__(self, routes: Mapping[int, can.BusABC]) -> None:
        if not routes:
            raise BusError("a merged bus needs at least one route")
        self.routes = dict(routes)
        self.buses = _distinct(self.routes.values())
        if not can_merge(self.buses):
            raise BusError("these CAN buses cannot be read as one (neither all in-process virtual buses nor all "
                           "with a file descriptor)")
        self._queue: queue.SimpleQueue[can.Message] | None = None
        self._ready: collections.deque[can.Message] = collections.deque()
        if isinstance(self.buses[0], FastVirtualBus):
            self._queue = queue.SimpleQueue()
            with channels_lock:
                for b in self.buses:
                    b.channel[next(i for i, q in enumerate(b.channel) if q is b.queue)] = self._queue
                    b.queue = self._queue
        self._by_fd = {} if self._queue is not None else {b.fileno(): b for b in self.buses}

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self._queue is not None:
            if self._ready:
                return self._ready.popleft()
            try:
                return unbatch(timed_get(self._queue, timeout), self._ready)
            except queue.Empty:
                return None
        if not self._ready:
            readable, _, _ = select.select(list(self._by_fd), [], [], timeout)
            for fd in readable:
                bus = self._by_fd[fd]
                while (msg := bus.recv(0)) is not None:
                    self._ready.append(msg)
        return self._ready.popleft() if self._ready else None

    def recv_pending(self) -> list[can.Message]:
        """Every frame queued now on any of the buses, in order, without waiting (`canbus.recv_pending`)."""
        if self._queue is not None:
            return take_queued(self._queue, self._ready)
        out = list(self._ready)
        self._ready.clear()
        for bus in self.buses:
            while (msg := bus.recv(0)) is not None:
                out.append(msg)
        return out

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        bus = self.routes.get(msg.arbitration_id >> CMD_BITS)
        if bus is None:
            raise can.CanOperationError(f"no bus for node {msg.arbitration_id >> CMD_BITS} (CAN id "
                                        f"0x{msg.arbitration_id:X}) on this merged bus")
        bus.send(msg, timeout=timeout)

    @property
    def batches(self) -> bool:
        """Merged virtual buses batch (`canbus.batches`); buses with a file descriptor send frame by frame."""
        return self._queue is not None and all(b.batches for b in self.buses)

    def send_batch(self, msgs: Sequence[can.Message], timeout: float | None = None) -> None:
        """`send` of each of `msgs`, in one `send_all` per bus (frames of one bus keep their order)."""
        by_bus: dict[int, tuple[Any, list[can.Message]]] = {}
        for msg in msgs:
            bus = self.routes.get(msg.arbitration_id >> CMD_BITS)
            if bus is None:
                self.send(msg, timeout)   # raises: no bus for that node
            by_bus.setdefault(id(bus), (bus, []))[1].append(msg)
        for bus, group in by_bus.values():
            send_all(bus, group)

    def shutdown(self) -> None:
        """Nothing to release: the merged buses are shut down by their owner."""

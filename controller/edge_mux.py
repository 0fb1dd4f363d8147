"""One edge per bus serving all its limbs: `EdgeMux` reads the bus once and hands every frame to the limb's edge
(`EdgeNode`, one per limb, not started as threads of their own: the I/O shell of that limb's `EdgeCore`) whose node
id the CAN id names (`can_id >> CMD_BITS`). Each limb's core keeps its own inner loop, link emulators and counters,
its shell its Zenoh keys; their commands go out on the shared bus handle.

Frames for no served node: well-formed ones (another device's traffic on a shared bus) are counted
(`foreign_frames`) and dropped, as a drive's acceptance filter would; malformed ones go to the first core, which
rejects and counts them (`rejected_frames`) as a lone edge does. Real time (`workers=False`): the bus reader calls
the core itself, one thread wakes per batch of frames (a driver tick's frames of every limb, read in one pass)
instead of one per limb, and the python-can `virtual` bus copies each frame to one reader instead of N. Lockstep (`workers=True`): a core blocks in its sync until its controller has
answered, so each core runs in a worker thread of its own fed by a queue; otherwise one limb whose controller has
finished its cycles (and answers no more) would stall the other limbs of its bus.
"""
from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Sequence
from typing import Any

import can

from sea_hil.controller.edge import EdgeNode, receive_all_stamped
from sea_hil.errors import ConfigError, MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import CMD_BITS
from sea_hil.protocol.canbus import CanHandle
from sea_hil.runtime.node import Node

log = logging.getLogger("sea_hil.edge")


class EdgeMux(Node):
    kind = "edge"

    def __init__(self, bus: CanHandle, edges: Sequence[EdgeNode], *, workers: bool = False) -> None:
        if not edges:
            raise ConfigError("an edge multiplexer needs at least one edge core")
        by_id = {e.node_id: e for e in edges}
        if len(by_id) != len(edges):
            raise ConfigError("edge cores on one bus need distinct node ids")
        super().__init__()
        self.bus, self.edges, self.by_id = bus, list(edges), by_id
        self.any_node = SeaCodec()
        self.foreign_frames = 0
        self.bus_errors = 0
        self._queues: dict[int, queue.SimpleQueue[tuple[can.Message, int]]] = \
            {e.node_id: queue.SimpleQueue() for e in edges} if workers else {}
        self._workers: list[threading.Thread] = []

    def _on_start(self, duration_s: float | None) -> None:
        self._workers = [threading.Thread(target=self._work, args=(e, self._queues[e.node_id]),
                                          name=f"edge-{e.node_id}", daemon=True) for e in self.edges if self._queues]
        for t in self._workers:
            t.start()

    def _on_stop(self) -> None:
        for t in self._workers:
            t.join(timeout=self.join_timeout_s)

    def _work(self, edge: EdgeNode, q: queue.SimpleQueue[tuple[can.Message, int]]) -> None:
        while not self.stop_event.is_set():
            try:
                msg, rx_ns = q.get(timeout=0.05)
            except queue.Empty:
                continue
            edge.on_can(msg, rx_ns)

    def _step(self) -> bool:
        got = receive_all_stamped(self.bus, self.stop_event, self._bus_error)   # every limb's frames in one pass
        for msg, rx_ns in got:
            self.dispatch(msg, rx_ns)
        return bool(got)

    def _bus_error(self, err: Exception) -> None:
        self.bus_errors += 1
        log.warning("CAN receive failed: %s", err)

    def dispatch(self, msg: can.Message, rx_ns: int) -> None:
        """Hand one frame (received at monotonic `rx_ns`) to the core of its node id."""
        edge = self.by_id.get(msg.arbitration_id >> CMD_BITS)
        if edge is None:
            try:
                self.any_node.decode(msg)
            except MalformedFrame:
                edge = self.edges[0]
            else:
                self.foreign_frames += 1
                return
        q = self._queues.get(edge.node_id)
        if q is not None:
            q.put((msg, rx_ns))
        else:
            edge.on_can(msg, rx_ns)

    def stop(self) -> None:
        super().stop()
        for e in self.edges:
            e.stop()

    def _close(self) -> None:
        for e in self.edges:
            e.close()

    def _stats(self) -> dict[str, Any]:
        return {"limbs": len(self.edges), "foreign_frames": self.foreign_frames, "bus_errors": self.bus_errors}

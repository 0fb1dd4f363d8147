"""The recorder node: every Zenoh message under `<prefix>/**` and every CAN frame on the bus into one MCAP file.

Binary payloads are decoded (rejects counted, raw size kept); JSON stats/tracking messages are flattened into
their channels. CAN frames go to `/can/raw` and, decoded with the DBC, to `/can/feedback` / `/can/command`
(`sea_hil.recorder.can_tap`). With an in-process `SessionRecorder` the node decodes and the recorder's writer thread
writes (bounded queue: a recorder that falls behind drops and counts); with a `RecorderProcess` the node only
forwards raw frames and Zenoh messages as they came, and the child process decodes, counts and writes.

On SocketCAN (and udp_multicast) the kernel drops frames silently when the tap's socket receive queue is full, so the node asks for a
large receive buffer (`sea_hil.protocol.canbus.enlarge_rx_buffer`; on udp_multicast too) and the frames that were missed anyway are counted from seq gaps
(`can_frames_missed`, `sea_hil.recorder.can_tap.SeqGapCounter`). The `ipc` bus drops nothing for a tap that keeps reading (its
senders wait instead); its gaps are counted the same way.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any

import can
import zenoh

from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.canbus import RX_BUFFER_BYTES, enlarge_rx_buffer
from sea_hil.protocol.keys import everything
from sea_hil.protocol.payloads import PayloadCounters
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.clock import TimeBase
from sea_hil.recorder.process import RecorderProcess
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.recorder.zenoh_tap import ZenohTap
from sea_hil.runtime.node import Node

__all__ = ["RecorderNode"]

log = logging.getLogger("sea_hil.record")
SHORT_PAUSE_S = 0.01         # a tap pause up to this long is a plain sleep (`RecorderNode._pause`)


def _enlarge_all(bus: Any, size_bytes: int) -> int | None:
    """`enlarge_rx_buffer` for a bus or for every bus a `MergedBus` reads; the smallest size granted."""
    sizes = [g for b in getattr(bus, "buses", [bus]) if (g := enlarge_rx_buffer(b, size_bytes)) is not None]
    return min(sizes) if sizes else None


class RecorderNode(Node):
    """A `Node` whose `run` keeps two taps (Zenoh, CAN) running until stopped; `close()` stops them (the CAN tap
    first records what is still queued on its socket, up to `tap_timeout_s`) and releases the subscriber."""

    kind = "recorder"
    join_timeout_s = None   # `_on_stop` bounds the taps' drain (`tap_timeout_s`); its counters must be final

    def __init__(self, recorder: SessionRecorder | RecorderProcess, session: zenoh.Session | None, prefix: str,
                 bus: can.BusABC | None = None, *, tap_batch_s: float = 0.0,
                 rx_buffer_bytes: int = RX_BUFFER_BYTES, tap_timeout_s: float = 10.0,
                 time_base: TimeBase = "wall") -> None:
        super().__init__()
        self.rec = recorder
        self.tap_batch_s = tap_batch_s
        self.tap_timeout_s = tap_timeout_s
        self.payloads = PayloadCounters()
        self.tap = CanTap(SeaCodec(fd=None), time_base)   # with a RecorderProcess, the child's tap (same time base) decodes
        self.ztap = ZenohTap(self.payloads, time_base)
        self.can_forwarded = 0   # frames shipped raw to a RecorderProcess (which counts and decodes them)
        self.can_tap_unfinished = False   # stop() gave up on a CAN backlog (frames not seen, not counted)
        self.zenoh_forwarded = 0   # messages shipped as they came to a RecorderProcess (which decodes and counts them)
        self.rx_buffer_bytes = _enlarge_all(bus, rx_buffer_bytes) if bus is not None else None
        self._sub = session.declare_subscriber(everything(prefix), zenoh.handlers.FifoChannel(65536)) \
            if session is not None else None
        self._bus = bus
        self._threads: list[threading.Thread] = []

    # ---- the node hooks -------------------------------------------------------------------------------------------
    def _on_start(self, duration_s: float | None) -> None:
        if self._bus is not None and self._sub is not None and self.tap_batch_s > 0:   # both taps pause: one thread
            self._threads = [threading.Thread(target=self._taps_loop, name="rec-taps", daemon=True)]
        else:
            self._threads = [threading.Thread(target=self._zenoh_loop, name="rec-zenoh", daemon=True)]
        if self._bus is not None and not self._threads[0].name == "rec-taps":
            self._threads.append(threading.Thread(target=self._can_loop, name="rec-can", daemon=True))
        for t in self._threads:
            t.start()

    def _step(self) -> bool:
        self.stop_event.wait(0.1)   # the taps do the work
        return False

    def _on_stop(self) -> None:
        """Wait for the taps; the CAN tap first records what is still queued on its socket."""
        self.stop_event.set()
        for t in self._threads:
            t.join(timeout=self.tap_timeout_s)
        self.can_tap_unfinished = any(t.is_alive() for t in self._threads if t.name in ("rec-can", "rec-taps"))
        if self.can_tap_unfinished:
            log.warning("CAN tap still draining its backlog after %.0f s: the rest is not recorded",
                        self.tap_timeout_s)

    def _close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()

    def _stats(self) -> dict[str, Any]:
        return {k: v for k, v in self.counters().items() if isinstance(v, (int, float)) and not isinstance(v, bool)}

    def _zenoh_loop(self) -> None:
        while self._sub is not None:
            s = self._sub.try_recv()
            if s is None:
                if self.stop_event.is_set():
                    return          # stopped, and what arrived up to now is recorded
                self._pause(max(0.001, self.tap_batch_s))   # idle: wait, then drain the batch
                continue
            self._on_zenoh(s)

    def _on_zenoh(self, s: zenoh.Sample) -> None:
        """Record one Zenoh message, taken at the wall time now (a `RecorderProcess` gets it as it came and decodes
        it in the child, as the CAN frames)."""
        if isinstance(self.rec, RecorderProcess):
            self.zenoh_forwarded += 1
            self.rec.submit_zenoh(str(s.key_expr), s.payload.to_bytes(), time.time_ns())
            return
        for r in self.ztap.take(str(s.key_expr), s.payload.to_bytes(), time.time_ns()):
            self.rec.submit(*r)

    def _taps_loop(self) -> None:
        """Both taps in one thread (`tap_batch_s` > 0, a bus and a session): take everything queued on the Zenoh
        subscriber and on the bus, then pause `tap_batch_s`. Each tap paused anyway; one thread wakes half as often
        and hands the GIL around less (docs/timing.md "Where the CPU goes"). On stop, what is queued is recorded."""
        assert self._sub is not None and self._bus is not None
        sub, bus = self._sub, self._bus
        while True:
            stopping = self.stop_event.is_set()
            while (s := sub.try_recv()) is not None:
                self._on_zenoh(s)
            frames = self._drain_bus(bus)
            if stopping:
                return
            if not frames and isinstance(self.rec, RecorderProcess):
                self.rec.flush(wait=False)   # idle bus: deliver what is batched, never block
            self._pause(self.tap_batch_s)

    def _can_loop(self) -> None:
        """Wait for a frame, take everything queued, then (`tap_batch_s` > 0) pause: the tap wakes once per batch
        rather than once per frame, leaving the CPU to the nodes; frames keep their bus timestamps. On stop, what
        is still queued is recorded before the loop ends."""
        assert self._bus is not None
        while not self.stop_event.is_set():
            msg = self._bus.recv(timeout=0.05)
            if msg is None:
                if isinstance(self.rec, RecorderProcess):
                    self.rec.flush(wait=False)   # idle bus: deliver what is batched, never block
                continue
            self.on_can(msg)
            self._drain_bus(self._bus)
            if self.tap_batch_s > 0:
                self._pause(self.tap_batch_s)
        self._drain_bus(self._bus)   # stopping: record what is still queued

    def _pause(self, s: float) -> None:
        """A tap's pause between batches. Up to `SHORT_PAUSE_S` a plain sleep: `Event.wait` with a timeout costs its
        thread ~2x the CPU of `time.sleep` (a Python-level condition and lock per call; measured 50 vs 29 us per
        2 ms wait on the loaded machine), and the taps pause up to 500 times a second; a stop then waits at most
        that long more. Longer pauses stay interruptible by `stop`."""
        if s <= SHORT_PAUSE_S:
            time.sleep(s)
        else:
            self.stop_event.wait(s)

    def _drain_bus(self, bus: can.BusABC) -> int:
        """Record every frame queued on `bus` (a `RecorderProcess` gets them as one batch); -> how many."""
        if not isinstance(self.rec, RecorderProcess):
            n = 0
            while (msg := bus.recv(timeout=0)) is not None:
                self.on_can(msg)
                n += 1
            return n
        frames, now_ns, recv = [], time.time_ns, bus.recv
        if self.tap.restamps:   # a cia402 bus on the sample time base: the tap's SYNC count times each frame
            stamp = self.tap.stamp
            while (msg := recv(timeout=0)) is not None:
                t = msg.timestamp
                frames.append((stamp(round(t * 1e9) if t > 0 else now_ns(), msg.arbitration_id, msg.is_extended_id),
                               msg.arbitration_id, msg.dlc, bytes(msg.data or b""),
                               bool(msg.is_extended_id), bool(msg.is_error_frame), bool(msg.is_remote_frame),
                               bool(msg.is_fd)))   # the fields of `RawFrame.of`, as a plain tuple
        else:                   # (`stamp` would return the bus time as it is)
            while (msg := recv(timeout=0)) is not None:
                t = msg.timestamp
                frames.append((round(t * 1e9) if t > 0 else now_ns(), msg.arbitration_id, msg.dlc,
                               bytes(msg.data or b""), bool(msg.is_extended_id), bool(msg.is_error_frame),
                               bool(msg.is_remote_frame), bool(msg.is_fd)))
        self.can_forwarded += len(frames)
        self.rec.submit_can_batch(frames)
        return len(frames)

    def on_can(self, msg: can.Message) -> None:
        """Record one frame, logged at its bus timestamp (receive time when the bus gives none)."""
        t_ns = self.tap.stamp(round(msg.timestamp * 1e9) if msg.timestamp > 0 else time.time_ns(),
                              msg.arbitration_id, msg.is_extended_id)
        frame = RawFrame.of(t_ns, msg)
        if isinstance(self.rec, RecorderProcess):
            self.can_forwarded += 1
            self.rec.submit_can(frame)    # decoded (rejects and gaps counted) by the recorder process
            return
        for m in self.tap.encode((frame,)):
            self.rec.submit_encoded(*m)

    def counters(self) -> dict[str, Any]:
        """Final-stats counters; with a `RecorderProcess` its child's CAN and Zenoh counts replace these in the
        file."""
        can_counts = self.tap.counters()
        if self.can_forwarded:
            can_counts["can_frames"] = self.can_forwarded
        rx = {} if self.rx_buffer_bytes is None else {"can_rx_buffer_bytes": self.rx_buffer_bytes}
        return {**can_counts, **rx, "can_tap_unfinished": int(self.can_tap_unfinished), **self.ztap.counters()}

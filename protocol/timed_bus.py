"""Bus handles clocked by the bus-timing model (`sea_hil.protocol.bus_timing`, `[can] emulate_bitrate = true`).

All handles of one channel in this process share one timeline (`timeline_for`), i.e. one `BusArbiter`:

- `RealTimeTimeline`: a frame is ready when `send` is called (monotonic clock); a thread puts each frame on the real
  bus (`raw.send` of the sending handle, so other processes see it too) when its transmission would end. Frames of
  other processes on a shared socketcan/udp bus are not in the model (on vcan the kernel-side equivalent is a `tc`
  shaper, docs/can-protocol.md).
- `LockstepTimeline`: simulated time, deterministic. Each handle has a simulated clock: a frame it sends is ready at
  that clock, a frame it receives moves the clock to the frame's delivery time, `advance_sim_time` moves it to a
  sample time (the driver before it publishes a sample). Frames go from handle to handle inside the process (not
  through the raw bus). The next frame is put on the simulated wire only when every handle is waiting in `recv`
  with nothing to read (except `listen_only` ones: a recorder), so every frame that could join its arbitration has
  been sent; one frame at a time.
  A frame equal (id and data) to the last one its handle sent with that id is a lockstep re-send: it takes no bus
  time and arrives stamped like the original. `rx_time_ns` is the simulated delivery time of the last frame read.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import can

from sea_hil.errors import ConfigError
from sea_hil.protocol.bus_timing import BusArbiter, BusRates, Transmission


class TimedBus:
    """A bus handle whose frames go through a timeline; everything else is the raw handle's."""

    def __init__(self, raw: can.BusABC, timeline: RealTimeTimeline | LockstepTimeline,
                 receive_own_messages: bool = False) -> None:
        self.raw, self.timeline = raw, timeline
        self.receive_own_messages = receive_own_messages
        self.simulated = isinstance(timeline, LockstepTimeline)
        self.inbox: deque[tuple[int, can.Message]] = deque()
        self.sim_now_ns = 0
        self.rx_time_ns = 0
        self.waiting = False
        self.listen_only = False    # lockstep: never answers a frame, so the simulation does not wait for it
        self.last_sent: dict[int, tuple[bytes, int]] = {}   # lockstep: id -> (data, delivery ns) of the last frame
        self.closed = False
        timeline.attach(self)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.timeline.submit(self, msg)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if not isinstance(self.timeline, LockstepTimeline):
            return self.raw.recv(timeout)
        return self.timeline.recv(self, timeout)

    def advance_sim_time(self, t_ns: int) -> None:
        """Lockstep: this handle's simulated clock moves on to `t_ns` (never back)."""
        self.sim_now_ns = max(self.sim_now_ns, int(t_ns))

    def shutdown(self) -> None:
        if not self.closed:
            self.closed = True
            self.timeline.detach(self)
            self.raw.shutdown()

    def timing_stats(self) -> dict[str, float]:
        """The bus's `/stats` fields (`BusArbiter.flat_stats`; real time: + `can_late_deliveries`, frames put on the
        bus more than 100 us after their transmission's end, i.e. the host could not keep up)."""
        out = self.timeline.arbiter.flat_stats()
        if isinstance(self.timeline, RealTimeTimeline):
            out["can_late_deliveries"] = self.timeline.late
        return out

    def __getattr__(self, name: str) -> Any:
        return getattr(self.raw, name)


class _Timeline:
    def __init__(self, rates: BusRates) -> None:
        self.arbiter = BusArbiter(rates)
        self.cond = threading.Condition()
        self.handles: list[TimedBus] = []

    def attach(self, h: TimedBus) -> None:
        with self.cond:
            self.handles.append(h)

    def detach(self, h: TimedBus) -> None:
        with self.cond:
            if h in self.handles:
                self.handles.remove(h)
            self.cond.notify_all()


class RealTimeTimeline(_Timeline):
    def __init__(self, rates: BusRates) -> None:
        super().__init__(rates)
        self.late = 0           # deliveries more than 100 us after their end (a loaded machine)
        self._thread: threading.Thread | None = None

    def attach(self, h: TimedBus) -> None:
        super().attach(h)
        with self.cond:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="can-bus-timing", daemon=True)
                self._thread.start()

    def submit(self, h: TimedBus, msg: can.Message) -> None:
        with self.cond:
            self.arbiter.submit(time.monotonic_ns(), msg, h)
            self.cond.notify_all()

    def _run(self) -> None:
        in_flight: Transmission | None = None
        with self.cond:
            while self.handles:
                now = time.monotonic_ns()
                if in_flight is not None and now >= in_flight.end_ns:
                    self.late += now - in_flight.end_ns > 100_000
                    _deliver_raw(in_flight)
                    in_flight = None
                if in_flight is None:
                    in_flight = self.arbiter.next_transmission(now)
                    if in_flight is not None:
                        continue
                wait_s = None if in_flight is None else max(in_flight.end_ns - now, 0) * 1e-9
                if wait_s is None and (start_ns := self.arbiter.next_start_ns()) is not None:
                    wait_s = max(start_ns - now, 0) * 1e-9
                self.cond.wait(wait_s)
            if in_flight is not None:
                _deliver_raw(in_flight)


def _deliver_raw(tx: Transmission) -> None:
    h: TimedBus = tx.token
    if not h.closed:
        try:
            h.raw.send(tx.msg)
        except (can.CanError, OSError):   # the sender's own send path counts failures; here the frame is lost
            pass


class LockstepTimeline(_Timeline):
    def submit(self, h: TimedBus, msg: can.Message) -> None:
        with self.cond:
            data = bytes(msg.data or b"")
            last = h.last_sent.get(msg.arbitration_id)
            if last is not None and last[0] == data:   # a lockstep re-send: no bus time, the original's stamp
                self._fan_out(h, last[1], msg)
                return
            h.last_sent[msg.arbitration_id] = (data, -1)
            self.arbiter.submit(h.sim_now_ns, msg, h)
            self.cond.notify_all()

    def recv(self, h: TimedBus, timeout: float | None) -> can.Message | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        with self.cond:
            h.waiting = True
            try:
                while not h.inbox:
                    self._advance()
                    if h.inbox:
                        break
                    remaining = None if deadline is None else deadline - time.monotonic()
                    if remaining is not None and remaining <= 0:
                        return None
                    self.cond.wait(remaining)
                t_ns, msg = h.inbox.popleft()
            finally:
                h.waiting = False
            h.rx_time_ns = t_ns
            h.sim_now_ns = max(h.sim_now_ns, t_ns)
            return msg

    def _advance(self) -> None:
        """Put frames on the simulated wire while every handle waits with nothing to read."""
        while self.arbiter.pending and all(o.waiting and not o.inbox or o.listen_only for o in self.handles):
            tx = self.arbiter.next_transmission()
            assert tx is not None
            sender: TimedBus = tx.token
            data = bytes(tx.msg.data or b"")
            if sender.last_sent.get(tx.msg.arbitration_id, (None,))[0] == data:
                sender.last_sent[tx.msg.arbitration_id] = (data, tx.end_ns)
            self._fan_out(sender, tx.end_ns, tx.msg)

    def _fan_out(self, sender: TimedBus, t_ns: int, msg: can.Message) -> None:
        if t_ns < 0:
            return   # the original is still queued: the re-send adds nothing
        stamp = time.time()
        for o in self.handles:
            if o is not sender or o.receive_own_messages:
                o.inbox.append((t_ns, can.Message(
                    timestamp=stamp, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                    is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame, dlc=msg.dlc,
                    data=bytearray(msg.data), is_fd=msg.is_fd, bitrate_switch=msg.bitrate_switch,
                    is_rx=o is not sender)))
        self.cond.notify_all()


def make_timeline(can_cfg: Any, spec: str, lockstep: bool) -> RealTimeTimeline | LockstepTimeline:
    """The timeline of bus `spec` for `[can]` (lockstep: simulated time, in-process `virtual` buses only)."""
    if lockstep and not spec.startswith("virtual:"):
        raise ConfigError(f"[can] emulate_bitrate in lockstep needs every CAN node in this process on a virtual bus, "
                          f"not {spec!r} (on vcan use a tc shaper, docs/can-protocol.md)")
    rates = BusRates.of(can_cfg)
    return LockstepTimeline(rates) if lockstep else RealTimeTimeline(rates)

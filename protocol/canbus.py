"""Open python-can buses from a one-string spec and send with a bounded retry when the transmit queue is full.

Specs: ``socketcan:IFNAME`` (e.g. ``socketcan:vcan0``), ``virtual:NAME`` (in-process python-can bus, for tests and
single-process runs; opened as `FastVirtualBus`), ``ipc:NAME`` (the lossless bus between the processes of one host,
`sea_hil.protocol.ipc_bus.IpcBus`) and ``udp_multicast:GROUP`` (python-can's UDP multicast bus between
processes/hosts; GROUP is an IPv4 or IPv6 multicast address such as ``239.74.163.2``, python-can's default port
43113; needs ``msgpack``). A udp_multicast bus is opened with a large socket receive buffer (`RX_BUFFER_BYTES`): with
the default 208 KiB a recorder that paused for a batch lost ~6 % of the frames of a four-process session (issue 32);
the kernel drops datagrams silently when the buffer is full, so the readers count the loss from sequence gaps.
"""
from __future__ import annotations

import collections
import errno
import logging
import queue
import socket
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import can
from can.interfaces.virtual import VirtualBus, channels_lock

from sea_hil.config.wire_names import parse_can_spec
from sea_hil.errors import BusError, ConfigError
from sea_hil.protocol.ipc_bus import IpcBus
from sea_hil.queues import timed_get


class CanHandle(Protocol):
    """What a node needs of its CAN bus: a python-can bus, or a handle built on one (the bus-timing model's
    `TimedBus`, several buses' `MergedBus`)."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...

    def recv(self, timeout: float | None = None) -> can.Message | None: ...


_CAN_LOG = logging.getLogger("can.bus")   # python-can's receive log (BusABC.recv)
_LOG = logging.getLogger("sea_hil.canbus")
# a node's 1 kHz loop waits at most this long per episode for an ipc member whose queue is full (one that joined and
# is not reading yet: a starting edge), then that member's frames are dropped and counted, as a CAN controller's
# overflowing receive buffer drops them: with IpcBus's default (1 s, for python-can users) a driver blocked in
# send missed its ticks and latched OVERRUN|VELOCITY_LIMIT after an edge restart (test_faults, fresh-clone CI)
NODE_SEND_TIMEOUT_S = 0.005
SO_RCVBUFFORCE = 33          # Linux <asm-generic/socket.h>; the socket module does not define it
RX_BUFFER_BYTES = 8 << 20   # the kernel doubles it: ~21k queued frames at ~770 B each, ~5 s of one 1 kHz limb


def bus_socket(bus: Any) -> socket.socket | None:
    """The receiving socket of a SocketCAN bus (`bus.socket`) or of python-can's udp_multicast bus (its private
    `_multicast._socket`: python-can exposes no accessor); None for other buses."""
    sock = getattr(bus, "socket", None)
    if sock is None:
        sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    return sock if isinstance(sock, socket.socket) else None


def enlarge_rx_buffer(bus: Any, size_bytes: int = RX_BUFFER_BYTES) -> int | None:
    """Raise the receive buffer of a bus's socket (`bus_socket`) to `size_bytes` (SO_RCVBUFFORCE as root, else
    SO_RCVBUF, which the kernel caps at net.core.rmem_max); -> the size the kernel granted, None for buses without a
    socket. A smaller grant is logged: frames may then be dropped by the kernel (counted by the readers)."""
    sock = bus_socket(bus)
    if sock is None:
        return None
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, size_bytes)
    except OSError:   # no CAP_NET_ADMIN: the capped request
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size_bytes)
        except OSError as err:
            _LOG.warning("cannot enlarge the CAN receive buffer: %s", err)
    granted = int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    if granted < size_bytes:
        _LOG.warning("CAN receive buffer is %d bytes (asked for %d; raise net.core.rmem_max): frames may be "
                     "dropped by the kernel", granted, size_bytes)
    return granted


def open_bus(spec: str, *, receive_own_messages: bool = False, fd: bool = False) -> can.BusABC:
    """Open the bus named by `spec` (classic CAN unless `fd`); `BusError` when it cannot be opened."""
    interface, channel = parse_can_spec(spec)
    kwargs: dict[str, Any] = {"receive_own_messages": receive_own_messages}
    if interface == "virtual":
        kwargs["protocol"] = can.CanProtocol.CAN_FD if fd else can.CanProtocol.CAN_20
    else:
        kwargs["fd"] = fd
    if interface == "udp_multicast" and receive_own_messages:
        raise BusError(f"cannot open {spec!r}: python-can's udp_multicast bus cannot receive its own messages")
    try:
        if interface == "virtual":
            return FastVirtualBus(channel=channel, **kwargs)
        if interface == "ipc":
            return IpcBus(channel=channel, send_timeout_s=NODE_SEND_TIMEOUT_S, **kwargs)
        bus = can.Bus(interface=interface, channel=channel, **kwargs)
        if interface == "udp_multicast":
            enlarge_rx_buffer(bus)
        return bus
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as err:
        hint = " (is the interface up? e.g. scripts/with-vcan)" if interface == "socketcan" else ""
        raise BusError(f"cannot open CAN bus {spec!r}: {err}{hint}") from err


class FastVirtualBus(VirtualBus):
    """python-can's `virtual` bus (same channels, so it shares a channel with plain `VirtualBus` instances) with the
    same delivery semantics at a fraction of the CPU cost: every receiver still gets its own copy of a frame (built
    directly, not through `copy.deepcopy`), and an unbounded receive queue (`rx_queue_size=0`, the default) is a C
    `queue.SimpleQueue` (FIFO, thread-safe, no Python-level condition variable) instead of a `queue.Queue`."""

    def __init__(self, channel: Any = "channel-0", receive_own_messages: bool = False, rx_queue_size: int = 0,
                 **kwargs: Any) -> None:
        super().__init__(channel=channel, receive_own_messages=receive_own_messages, rx_queue_size=rx_queue_size,
                         **kwargs)
        if rx_queue_size == 0:
            with channels_lock:
                i = next(i for i, q in enumerate(self.channel) if q is self.queue)
                self.queue = self.channel[i] = queue.SimpleQueue()  # type: ignore[assignment,call-overload]

        self._ready: collections.deque[can.Message] = collections.deque()   # the rest of a received `FrameBatch`

    @property
    def batches(self) -> bool:
        """`send_batch` never fills a queue: every queue on the channel is unbounded (`canbus.batches`)."""
        queues: list[Any] = self.channel
        return all(type(q) is queue.SimpleQueue for q in queues)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """`BusABC.recv` without its generic filter loop when no filters are set (a plain queue read)."""
        if self._filters or not isinstance(self.queue, queue.SimpleQueue):
            return super().recv(timeout)
        self._check_if_open()
        if self._ready:
            msg = self._ready.popleft()
        else:
            try:
                item = timed_get(self.queue, timeout)   # not `get(timeout=)`: it can hang (sea_hil.queues)
            except queue.Empty:
                return None
            msg = unbatch(item, self._ready)
        if _CAN_LOG.isEnabledFor(self.RECV_LOGGING_LEVEL):
            _CAN_LOG.log(self.RECV_LOGGING_LEVEL, "Received: %s", msg)
        return msg

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        """python-can's filtered `recv` path: a `FrameBatch` on the queue is handed out frame by frame."""
        if self._ready:
            return self._ready.popleft(), False
        msg, filtered = super()._recv_internal(timeout)
        return (None if msg is None else unbatch(msg, self._ready)), filtered

    def recv_pending(self) -> list[can.Message]:
        """Every frame queued now, in order, without waiting (one pass, no exception per empty read)."""
        if self._filters or not isinstance(self.queue, queue.SimpleQueue):
            return _recv_each(self)
        self._check_if_open()
        out = take_queued(self.queue, self._ready)
        if out and _CAN_LOG.isEnabledFor(self.RECV_LOGGING_LEVEL):
            for msg in out:
                _CAN_LOG.log(self.RECV_LOGGING_LEVEL, "Received: %s", msg)
        return out

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """`VirtualBus.send`: a copy to every other bus on the channel (to this one too with
        `receive_own_messages`), stamped with the send time unless `preserve_timestamps`."""
        self.send_batch((msg,), timeout)

    def send_batch(self, msgs: Sequence[can.Message], timeout: float | None = None) -> None:
        """`send` of each of `msgs` in order, stamped with one send time, each receiver's copies put on its queue at
        once: a `FrameBatch` (one queue item, so a waiting reader wakes once for all) on the queues of this class and
        of `MergedBus`, frame by frame on other queues (plain python-can `VirtualBus` handles)."""
        self._check_if_open()
        now = time.time()
        all_sent = True
        queues: list[Any] = self.channel
        for bus_queue in queues:
            if bus_queue is self.queue and not self.receive_own_messages:
                continue
            is_rx = bus_queue is not self.queue
            copies = [received_copy(m, m.timestamp if self.preserve_timestamps else now, self.channel_id, is_rx)
                      for m in msgs]
            try:
                if type(bus_queue) is queue.SimpleQueue:   # unbounded: never Full
                    bus_queue.put(copies[0] if len(copies) == 1 else FrameBatch(copies))
                else:
                    for c in copies:
                        bus_queue.put(c, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")


class FrameBatch(list[can.Message]):
    """Several frames put on a receiver's queue as one item by `FastVirtualBus.send_batch`; every reader of such a
    queue (`FastVirtualBus`, `MergedBus`) hands them out one by one (`unbatch`)."""


def unbatch(item: Any, ready: collections.deque[can.Message]) -> can.Message:
    """The frame `item` is, or the first of a `FrameBatch` (the others appended to `ready`)."""
    if type(item) is FrameBatch:
        ready.extend(item[1:])
        item = item[0]
    msg: can.Message = item
    return msg


def take_queued(q: Any, ready: collections.deque[can.Message]) -> list[can.Message]:
    """The frames in `ready` (the rest of a batch already read), then every frame on the queue `q` now, unbatched,
    in order; `ready` is emptied. One consumer per queue: what `empty` saw is still there to get."""
    out = list(ready)
    ready.clear()
    while not q.empty():
        item = q.get_nowait()
        if type(item) is FrameBatch:
            out += item
        else:
            out.append(item)
    return out


def _recv_each(bus: Any) -> list[can.Message]:
    out = []
    while (msg := bus.recv(timeout=0)) is not None:
        out.append(msg)
    return out


def recv_pending(bus: Any) -> list[can.Message]:
    """Every frame queued on `bus` now, without waiting: one pass (`recv_pending`) on the buses that have one
    (`FastVirtualBus`, `MergedBus`), else `recv(timeout=0)` until none. The exact type is checked, not the attribute:
    a `TimedBus` forwards unknown attributes to its raw bus, whose queue it must not bypass."""
    if type(bus) is FastVirtualBus or getattr(type(bus), "recv_pending", None) is not None:
        out: list[can.Message] = bus.recv_pending()
        return out
    return _recv_each(bus)


def batches(bus: Any) -> bool:
    """Does `bus` send a tick's frames in one `send_batch` that cannot fill up (`FastVirtualBus` with unbounded
    queues, a `MergedBus` of them)? The type is asked first, as in `recv_pending`."""
    return getattr(type(bus), "send_batch", None) is not None and bool(bus.batches)


def send_all(bus: Any, msgs: Sequence[can.Message]) -> None:
    """Send `msgs` in order: in one `send_batch` where the bus `batches` (one wake of each reader), else frame by
    frame."""
    if batches(bus):
        bus.send_batch(msgs)
    else:
        for m in msgs:
            bus.send(m)


def rx_monotonic_ns(frame_timestamp_s: float, mono_now_ns: int, wall_now_ns: int, *,
                    max_age_ns: int = 10**10) -> int:
    """The monotonic time at which a frame stamped `frame_timestamp_s` (python-can: wall clock, set by the sender on
    the virtual bus, by the kernel on SocketCAN) arrived, so queueing and wake-up count in the loop time; `mono_now_ns`
    when the stamp is missing or implausible (in the future or older than `max_age_ns`)."""
    age_ns = wall_now_ns - int(frame_timestamp_s * 1e9)
    return mono_now_ns - age_ns if 0 <= age_ns <= max_age_ns else mono_now_ns


_new_message = object.__new__


def received_copy(msg: can.Message, timestamp: float, channel: Any, is_rx: bool) -> can.Message:
    """What `can.Message(timestamp=timestamp, arbitration_id=msg.arbitration_id, ..., channel=channel, dlc=msg.dlc,
    data=bytearray(msg.data), is_rx=is_rx, ...)` builds (every other field copied from `msg`), slot by slot: the
    constructor's keyword handling cost ~4 us a copy, this ~1.3 us, and a 1 kHz limb makes ~8 copies a sample
    (tests/test_canbus.py checks every slot against the constructor's copy)."""
    c = _new_message(can.Message)
    c.timestamp = timestamp
    c.arbitration_id = msg.arbitration_id
    c.is_extended_id = msg.is_extended_id
    c.is_remote_frame = remote = msg.is_remote_frame
    c.is_error_frame = msg.is_error_frame
    c.channel = channel
    c.is_fd = msg.is_fd
    c.is_rx = is_rx
    c.bitrate_switch = msg.bitrate_switch
    c.error_state_indicator = msg.error_state_indicator
    c.data = bytearray() if remote else bytearray(msg.data)
    c.dlc = msg.dlc
    return c


def is_buffer_full(err: BaseException) -> bool:
    """True for the transient 'transmit queue full' failures (ENOBUFS, python-can's 'Transmit buffer full')."""
    if getattr(err, "error_code", None) == errno.ENOBUFS or getattr(err, "errno", None) == errno.ENOBUFS:
        return True
    cause = err.__cause__
    if isinstance(cause, OSError) and cause.errno == errno.ENOBUFS:
        return True
    return isinstance(err, can.CanOperationError) and "buffer full" in str(err).lower()


def send_with_retry(bus: CanHandle, msg: can.Message, retries: int, backoff_s: float, *,
                    timeout_s: float | None = None, sleep: Callable[[float], None] = time.sleep) -> int:
    """Send `msg`, retrying up to `retries` times (sleeping `backoff_s` in between) while the transmit queue is full.

    Returns the number of retries used; raises `BusError` on any other send failure at once and on a full queue
    after the last retry. Worst-case blocking is ``retries * backoff_s`` plus the send timeouts.
    """
    if retries < 0 or not backoff_s >= 0:
        raise ConfigError(f"send_with_retry: retries {retries!r} and backoff_s {backoff_s!r} must be >= 0")
    last: BaseException | None = None
    for attempt in range(retries + 1):
        if attempt:
            sleep(backoff_s)
        try:
            bus.send(msg, timeout=timeout_s)
            return attempt
        except (can.CanError, OSError) as err:
            if not is_buffer_full(err):
                raise BusError(f"CAN send of id 0x{msg.arbitration_id:X} failed: {err}") from err
            last = err
    raise BusError(f"CAN transmit queue still full after {retries} retries (id 0x{msg.arbitration_id:X}): {last}")

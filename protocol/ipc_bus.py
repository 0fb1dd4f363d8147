"""`ipc:NAME`: a lossless CAN bus between the processes of one host, over AF_UNIX SOCK_SEQPACKET sockets.

Why (issue 32/33): python-can's `udp_multicast` bus loses frames whenever a receiver's socket buffer overflows (the
kernel drops UDP datagrams silently), 8-15 frames per 10 s real-time session even with 8 MiB buffers. This bus
never drops a frame a member can still take: a sender that finds a receiver's queue full waits for it.

How: every member of channel NAME listens on its own socket file in the channel's directory (`channel_dir`: under
`$XDG_RUNTIME_DIR`, else `/tmp/sea-hil-can-<uid>`; no port). `send` writes the frame (`sea_hil.protocol.ipc_wire`)
on one connection to each other member, found by listing the directory when its modification time changed; a new
member is bound under a hidden name and renamed into place once it listens, so it is never seen half-made. A
connection is FIFO, so each sender's frames arrive in order; a member sees only frames sent after it joined.
Flow control is the kernel's: a connection queues up to its send buffer (`SNDBUF_BYTES` asked; ~10,900 frames at
the 8 MiB the kernel grants for 4 MiB when `net.core.wmem_max` allows, ~550 at the common 208 KiB cap), then the
sender waits for the receiver to read, retrying as room comes, nothing lost. The waits for one member add up to at
most `send_timeout_s` per episode of a full queue (until it has read its queue down to a quarter); a member that
needs more (stopped, hung, too slow) is marked stuck: the frame is dropped for it alone and counted
(`frames_dropped`, logged), its later frames are dropped without waiting until it has read its queue down to a
quarter; the others still get everything. So a real-time sender is held back at most `send_timeout_s` an episode. A member that died is detected by its
connection (EPIPE/ECONNRESET) or its socket file (ECONNREFUSED: the stale file is removed), never waited for.
`recv` reads one packet at a time from the members' connections (round robin, nothing buffered in this process), so
`fileno()` (an epoll descriptor over them) is readable exactly while a frame is pending: select-based readers
(`MergedBus`, python-can's Notifier) work. A packet that is not a valid frame is counted (`frames_malformed`),
logged and dropped. Timestamps are the send time (`ipc_wire`). Own frames come back only with
`receive_own_messages=True` (through a connection to itself, like any member). One host only: the sockets are
files; between hosts use SocketCAN or `udp_multicast`.
"""
from __future__ import annotations

import collections
import errno
import logging
import math
import os
import secrets
import select
import socket
import threading
import time
from pathlib import Path
from typing import Any

import can

from sea_hil.config.wire_names import validate_ipc_channel
from sea_hil.errors import ConfigError, MalformedFrame
from sea_hil.protocol.ipc_wire import MAX_PACKET_BYTES, decode_frame, encode_frame

log = logging.getLogger("sea_hil.ipc_bus")

SNDBUF_BYTES = 4 << 20            # asked per connection (the kernel doubles it, capped by net.core.wmem_max)
SO_SNDBUFFORCE = 32               # Linux <asm-generic/socket.h>: past wmem_max, needs CAP_NET_ADMIN
SEND_TIMEOUT_S = 1.0              # how long a sender waits for a member whose queue is full before dropping for it
RETRY_S = 0.001                   # a waiting sender tries again this often (the kernel's POLLOUT comes only once the
                                  # queue is down to a quarter: a slow reader frees room long before)
SCAN_SETTLE_NS = 100_000_000      # a directory listing made this soon after its mtime may miss a change in the
                                  # same coarse filesystem tick (a few ms): list again on the next send
_FD_SETSIZE = 1024                # select's descriptor limit (above it: epoll's millisecond wait)
SUN_PATH_MAX = 107                # sockaddr_un.sun_path (108) minus the NUL
_SUFFIX = ".sock"
_GONE = (errno.EPIPE, errno.ECONNRESET, errno.ENOTCONN, errno.ECONNREFUSED, errno.ENOENT)


def channel_dir(channel: str, base: str | os.PathLike[str] | None = None) -> Path:
    """The directory of `channel`'s member sockets: `base`/NAME, by default under `$XDG_RUNTIME_DIR/sea-hil-can`
    (per user, on tmpfs), else `/tmp/sea-hil-can-<uid>`."""
    validate_ipc_channel(channel)
    if base is None:
        runtime = os.environ.get("XDG_RUNTIME_DIR", "")
        base = Path(runtime) / "sea-hil-can" if runtime and Path(runtime).is_dir() \
            else Path("/tmp") / f"sea-hil-can-{os.getuid()}"
    return Path(base) / channel


class _Peer:
    """One other member as seen by a sender: the connection to its socket and whether it is stuck."""

    __slots__ = ("name", "sock", "stuck", "dropped", "waited_s")

    def __init__(self, name: str, sock: socket.socket) -> None:
        self.name = name
        self.sock = sock
        self.stuck = False
        self.dropped = 0
        self.waited_s = 0.0   # waited for it in the current episode of a full queue (0: none)


class IpcBus(can.BusABC):
    """The `ipc` bus (module docstring). python-can entry point `ipc` (`can.Bus(interface="ipc", channel=NAME)`),
    sea-hil spec `ipc:NAME`. `send(msg, timeout)`: `timeout` bounds the waits for a full member in one episode (None:
    `send_timeout_s`, not forever: a stopped member must not stop the bus); it raises only for an invalid frame or a
    closed bus. Counters: `frames_sent`, `frames_received`, `frames_dropped` (for stuck members), `frames_malformed`,
    `members_lost` (members that died or left), `send_waits` (episodes of waiting for a full member)."""

    def __init__(self, channel: Any = "sea-hil", can_filters: can.typechecking.CanFilters | None = None,
                 receive_own_messages: bool = False, fd: bool = False, directory: str | None = None,
                 send_timeout_s: float = SEND_TIMEOUT_S, sndbuf_bytes: int = SNDBUF_BYTES, **kwargs: Any) -> None:
        try:
            self._dir = channel_dir(str(channel), directory)
        except ConfigError as err:
            raise can.CanInitializationError(str(err)) from err
        if not send_timeout_s >= 0:
            raise can.CanInitializationError(f"send_timeout_s must be >= 0, got {send_timeout_s!r}")
        self.channel_name = str(channel)
        self.channel_info = f"ipc channel {self.channel_name!r} ({self._dir})"
        self.receive_own_messages = receive_own_messages
        self.send_timeout_s = float(send_timeout_s)
        self._sndbuf_bytes = sndbuf_bytes
        self._can_protocol = can.CanProtocol.CAN_FD if fd else can.CanProtocol.CAN_20
        self.frames_sent = self.frames_received = self.frames_dropped = self.frames_malformed = 0
        self.members_lost = 0
        self.send_waits = 0   # episodes of a member's full queue the senders waited in (flow control at work)
        self._peers: dict[str, _Peer] = {}
        self._send_lock = threading.Lock()
        self._seen_mtime_ns: int | None = None
        self._scan_settled = False
        self._in: dict[int, socket.socket] = {}
        self._ready: collections.deque[int] = collections.deque()
        self._listener, self._name = self._join()
        self._path = self._dir / self._name
        # the directory holds this member's file, so it stays (rmdir fails) while this bus is open: fstat of a
        # descriptor is ~1 us cheaper a send than stat of the path
        self._dir_fd = os.open(self._dir, os.O_RDONLY | os.O_DIRECTORY)
        self._epoll = select.epoll()
        self._epoll.register(self._listener.fileno(), select.EPOLLIN)
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)

    # ---- membership -----------------------------------------------------------------------------------------------
    def _join(self) -> tuple[socket.socket, str]:
        """Listen on a fresh socket in the channel directory; -> (listener, its file name). Bound under a hidden
        name and renamed once listening (a sender never connects to a member that cannot accept yet)."""
        token = f"{os.getpid()}-{secrets.token_hex(4)}"
        name, hidden = token + _SUFFIX, f".{token}.tmp"
        if len(str(self._dir / hidden)) > SUN_PATH_MAX:
            raise can.CanInitializationError(f"ipc socket path under {self._dir} is longer than {SUN_PATH_MAX} "
                                             "bytes: use a shorter channel name or directory")
        for attempt in range(3):   # a last member leaving removes the directory: make it again
            self._make_dir()
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            try:
                sock.bind(str(self._dir / hidden))
                sock.listen(socket.SOMAXCONN)
                sock.setblocking(False)
                os.rename(self._dir / hidden, self._dir / name)
                return sock, name
            except FileNotFoundError:
                sock.close()
                if attempt == 2:
                    raise
            except OSError as err:
                sock.close()
                raise can.CanInitializationError(f"cannot join {self.channel_info}: {err}") from err
        raise AssertionError("unreachable")

    def _make_dir(self) -> None:
        self._dir.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        self._dir.mkdir(mode=0o700, exist_ok=True)
        owner = self._dir.stat().st_uid
        if owner != os.getuid():
            raise can.CanInitializationError(f"{self._dir} belongs to uid {owner}, not to this user")

    def _refresh_peers(self) -> None:
        """Connect to members that joined, forget members whose file is gone (the directory listed again only when
        its mtime changed, or when the last listing was too close to that mtime to be sure: `SCAN_SETTLE_NS`)."""
        mtime_ns = os.fstat(self._dir_fd).st_mtime_ns
        if mtime_ns == self._seen_mtime_ns and self._scan_settled:
            return
        t_scan_ns = time.time_ns()
        try:
            names = {e.name for e in os.scandir(self._dir) if e.name.endswith(_SUFFIX) and not e.name.startswith(".")}
        except FileNotFoundError:
            names = set()
        self._seen_mtime_ns, self._scan_settled = mtime_ns, t_scan_ns - mtime_ns >= SCAN_SETTLE_NS
        if not self.receive_own_messages:
            names.discard(self._name)
        for name in [n for n in self._peers if n not in names]:
            self._forget(name, "left")
        for name in sorted(names - self._peers.keys()):
            self._connect(name)

    def _connect(self, name: str) -> None:
        path = self._dir / name
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            try:
                sock.setsockopt(socket.SOL_SOCKET, SO_SNDBUFFORCE, self._sndbuf_bytes)
            except OSError:   # no CAP_NET_ADMIN: capped at net.core.wmem_max
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self._sndbuf_bytes)
            sock.settimeout(self.send_timeout_s)
            sock.connect(str(path))
            sock.setblocking(False)
        except ConnectionRefusedError:   # a socket file nobody listens on: its member died without removing it
            sock.close()
            self.members_lost += 1
            log.info("%s: removing the socket of a dead member (%s)", self.channel_info, name)
            try:
                path.unlink()
            except FileNotFoundError:
                pass
            return
        except OSError as err:           # gone meanwhile, or its accept queue full: try again on the next send
            sock.close()
            if not isinstance(err, FileNotFoundError):
                log.warning("%s: cannot connect to member %s: %s", self.channel_info, name, err)
                self._scan_settled = False
            return
        self._peers[name] = _Peer(name, sock)

    def _forget(self, name: str, why: str) -> None:
        peer = self._peers.pop(name)
        peer.sock.close()
        self.members_lost += 1
        log.debug("%s: member %s %s", self.channel_info, name, why)

    @property
    def member_count(self) -> int:
        """The other members this bus sent to on its last send (itself too with `receive_own_messages`)."""
        return len(self._peers)

    # ---- send -----------------------------------------------------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self._is_shutdown:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        try:
            packet = encode_frame(msg, time.time_ns())
        except MalformedFrame as err:
            raise can.CanOperationError(f"cannot send on {self.channel_info}: {err}") from err
        wait_s = self.send_timeout_s if timeout is None else max(0.0, timeout)
        with self._send_lock:
            self._refresh_peers()
            for peer in list(self._peers.values()):
                self._deliver(peer, packet, wait_s)
            self.frames_sent += 1

    def _deliver(self, peer: _Peer, packet: bytes, wait_s: float) -> None:
        """Send `packet` to one member: at once when its queue has room; else retry as room comes (`_writable`, at
        most every `RETRY_S`), so a reader that catches up holds the sender back no longer than it must. The waits
        of one episode of a full queue (until the queue is down to a quarter, the kernel's writable mark) add up to
        at most `wait_s`: past it the member is stuck, and gets frames again only once down to a quarter. So a
        real-time sender is held back at most `wait_s` per episode, however slowly a member reads."""
        if peer.stuck or peer.waited_s:
            if not _writable(peer.sock, 0.0):
                if peer.stuck:
                    self._drop(peer)
                    return
            elif peer.stuck:
                peer.stuck, peer.waited_s = False, 0.0
                log.warning("%s: member %s reads again (%d frames dropped for it)", self.channel_info, peer.name,
                            peer.dropped)
            else:
                peer.waited_s = 0.0   # caught up: the episode is over
        t0 = None
        while True:
            try:
                peer.sock.send(packet)
                break
            except BlockingIOError:
                now = time.monotonic()
                if t0 is None:
                    t0 = now
                    self.send_waits += peer.waited_s == 0.0
                spent_s = peer.waited_s + (now - t0)
                if spent_s >= wait_s:
                    peer.stuck, peer.waited_s = True, 0.0
                    log.warning("%s: member %s kept its queue full for %.3g s of waiting: dropping frames for it "
                                "until it catches up", self.channel_info, peer.name, wait_s)
                    self._drop(peer)
                    return
                _writable(peer.sock, min(RETRY_S, wait_s - spent_s))
            except OSError as err:
                if err.errno in _GONE:   # it died or left: look at its file on the next send
                    self._forget(peer.name, f"gone ({err})")
                    self._scan_settled = False
                    return
                raise can.CanOperationError(f"send on {self.channel_info} to {peer.name} failed: {err}") from err
        if t0 is not None:
            peer.waited_s += max(time.monotonic() - t0, 1e-9)

    def _drop(self, peer: _Peer) -> None:
        peer.dropped += 1
        self.frames_dropped += 1

    # ---- receive --------------------------------------------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._is_shutdown:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            msg = self._read_ready()
            if msg is not None:
                return msg, False
            if deadline is None:
                events = self._epoll.poll(-1)
            else:
                remaining = deadline - time.monotonic()
                events = self._wait(max(0.0, remaining))
                if not events and remaining <= 0:
                    return None, False
            self._ready.extend(fd for fd, _ in events)

    def _wait(self, timeout_s: float) -> list[tuple[int, int]]:
        """epoll's events within `timeout_s`. epoll_wait counts whole milliseconds (CPython rounds up: a 0.3 ms wait
        lasts 1 ms, which made a 1 kHz driver on this bus late by up to a period), so the wait is a `select` on
        the epoll descriptor (microseconds) where its number fits select's set."""
        if self._epoll.fileno() >= _FD_SETSIZE:
            return self._epoll.poll(timeout_s)
        readable, _, _ = select.select([self._epoll.fileno()], [], [], timeout_s)
        return self._epoll.poll(0) if readable else []

    def _read_ready(self) -> can.Message | None:
        """The next valid frame from the connections epoll said were readable (each read once in turn), None when
        they are drained; accepts new members' connections on the way."""
        listener = self._listener.fileno()
        while self._ready:
            fd = self._ready.popleft()
            if fd == listener:
                self._accept()
                continue
            conn = self._in.get(fd)
            if conn is None:
                continue
            try:
                packet = conn.recv(MAX_PACKET_BYTES + 1)   # a longer packet arrives truncated: malformed
            except BlockingIOError:
                continue
            except OSError:
                self._close_in(fd)
                continue
            if not packet and _hung_up(conn):
                self._close_in(fd)
                continue
            if fd not in self._ready:
                self._ready.append(fd)
            try:
                msg = decode_frame(packet, self.channel_name)
            except MalformedFrame as err:
                self.frames_malformed += 1
                if self.frames_malformed <= 10 or self.frames_malformed % 1000 == 0:
                    log.warning("%s: dropped malformed packet #%d: %s", self.channel_info, self.frames_malformed,
                                err)
                continue
            self.frames_received += 1
            return msg
        return None

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            conn.setblocking(False)
            self._in[conn.fileno()] = conn
            self._epoll.register(conn.fileno(), select.EPOLLIN)
            self._ready.append(conn.fileno())

    def _close_in(self, fd: int) -> None:
        conn = self._in.pop(fd)
        self._epoll.unregister(fd)
        conn.close()

    def fileno(self) -> int:
        """An epoll descriptor readable while a frame (or a new member's connection) is pending."""
        return self._epoll.fileno()

    # ---- leave ----------------------------------------------------------------------------------------------------
    def shutdown(self) -> None:
        """Leave the bus: remove this member's socket file, close every connection (the directory too when this was
        the last member)."""
        if self._is_shutdown:
            return
        super().shutdown()
        if self.frames_dropped:
            log.warning("%s: %d frame(s) sent were dropped for stuck members (%s)", self.channel_info,
                        self.frames_dropped, ", ".join(f"{p.name}: {p.dropped}" for p in self._peers.values()
                                                       if p.dropped) or "members since gone")
        try:
            self._path.unlink()
        except FileNotFoundError:
            pass
        self._listener.close()
        with self._send_lock:
            for peer in self._peers.values():
                peer.sock.close()
            self._peers.clear()
        for conn in self._in.values():
            conn.close()
        self._in.clear()
        self._epoll.close()
        os.close(self._dir_fd)
        try:
            self._dir.rmdir()
        except OSError:   # other members (or a joining one) still there
            pass


def _writable(sock: socket.socket, wait_s: float) -> bool:
    """Wait up to `wait_s` for `sock`'s send queue to be down to a quarter of its buffer (the kernel's POLLOUT; a
    closed peer also ends the wait)."""
    poller = select.poll()
    poller.register(sock, select.POLLOUT)
    return bool(poller.poll(max(0, math.ceil(wait_s * 1000))))


def _hung_up(conn: socket.socket) -> bool:
    """True when an empty read was the end of the connection (its member left), False for an empty packet."""
    poller = select.poll()
    poller.register(conn, select.POLLIN | select.POLLRDHUP)
    return any(ev & (select.POLLRDHUP | select.POLLHUP) for _, ev in poller.poll(0))

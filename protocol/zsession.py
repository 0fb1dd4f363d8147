"""Helpers on the zenoh 1.x Python API: explicit-endpoint sessions, control publishers, link-emulated publishers (the
newest-only subscriber is `sea_hil.protocol.zlatest`).

Sessions never rely on multicast scouting: one side listens on e.g. `tcp/127.0.0.1:<port>`, the other connects.
With `[zenoh.tls]` / `[zenoh.acl]` enabled (the secure profile, docs/security.md) `session_config` adds mutual TLS
and access control from `sea_hil.protocol.zsecurity`.
"""
from __future__ import annotations

import json
import re
import socket
import threading
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import zenoh

from sea_hil.config.comms import ZenohConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.link import DelayQueue, LinkEmulator
from sea_hil.protocol.wire_size import estimate_wire_bytes
from sea_hil.protocol.zsecurity import check_tls_files, security_settings

_ENDPOINT = re.compile(r"^[a-z0-9\-]+/\S+$")
_MODES = ("peer", "client", "router")


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago (the OS may hand it out again; bind promptly)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def _insert(cfg: zenoh.Config, key: str, value: Any) -> None:
    try:
        cfg.insert_json5(key, json.dumps(value))
    except zenoh.ZError as err:
        raise ConfigError(f"zenoh config {key}={value!r} rejected: {err}") from err


def make_config(*, listen: list[str] | tuple[str, ...] = (), connect: list[str] | tuple[str, ...] = (),
                mode: str = "peer", settings: Mapping[str, Any] | None = None) -> zenoh.Config:
    """A zenoh config with multicast scouting off and only the given endpoints (`<proto>/<address>`).

    `settings` are extra `{json5 path: value}` entries (e.g. `sea_hil.protocol.zsecurity.security_settings`).
    """
    if mode not in _MODES:
        raise ConfigError(f"zenoh mode {mode!r} must be one of {', '.join(_MODES)}")
    for ep in (*listen, *connect):
        if not isinstance(ep, str) or not _ENDPOINT.match(ep):
            raise ConfigError(f"zenoh endpoint {ep!r} must look like 'tcp/127.0.0.1:7447'")
    cfg = zenoh.Config()
    _insert(cfg, "mode", mode)
    _insert(cfg, "scouting/multicast/enabled", False)
    _insert(cfg, "listen/endpoints", list(listen))
    _insert(cfg, "connect/endpoints", list(connect))
    for key, value in (settings or {}).items():
        _insert(cfg, key, value)
    return cfg


def session_config(z: ZenohConfig) -> zenoh.Config:
    """The zenoh config of a `[zenoh]` section, including the secure profile when enabled."""
    check_tls_files(z.tls)
    return make_config(listen=z.listen, connect=z.connect, mode=z.mode, settings=security_settings(z))


def open_session(cfg: zenoh.Config | ZenohConfig) -> zenoh.Session:
    """Open a session; an unusable endpoint or config raises `ConfigError`. Close it with `session.close()`."""
    if isinstance(cfg, ZenohConfig):
        cfg = session_config(cfg)
    try:
        return zenoh.open(cfg)
    except zenoh.ZError as err:
        raise ConfigError(f"cannot open zenoh session: {err}") from err


def publisher(session: zenoh.Session, key: str, *, express: bool = True,
              priority: zenoh.Priority = zenoh.Priority.REAL_TIME,
              congestion_control: zenoh.CongestionControl = zenoh.CongestionControl.DROP) -> zenoh.Publisher:
    """A publisher for control traffic: by default unbatched (express), highest priority, drop when congested."""
    return session.declare_publisher(key, express=express, priority=priority, congestion_control=congestion_control)


def await_subscriber(pub: zenoh.Publisher, timeout_s: float) -> bool:
    """Whether a subscriber matches `pub`'s key, waiting up to `timeout_s` for one: Zenoh's matching status, true once
    a subscription declared elsewhere (a recorder across a slow link) has reached this session. A matching listener
    wakes the wait (no polling)."""
    if _matching(pub):
        return True
    matched = threading.Event()
    listener = pub.declare_matching_listener(lambda status: matched.set() if status.matching else None)
    try:
        return _matching(pub) or matched.wait(max(0.0, timeout_s))
    finally:
        listener.undeclare()


def _matching(pub: zenoh.Publisher) -> bool:
    status: Any = pub.matching_status   # a zenoh.MatchingStatus (zenoh 1.x's stubs say bool)
    return bool(getattr(status, "matching", status))


class _Putter(Protocol):
    def put(self, payload: bytes) -> Any: ...


class LinkedPublisher:
    """A publisher behind a `LinkEmulator`, driven explicitly by its owner's loop (no thread, no clock reads).

    `put(data, now_ns)` runs the emulator; a kept message is published at once if it is due and nothing is
    queued before it, otherwise held in a `DelayQueue`. The owner calls `poll(now_ns)` every tick (or sleeps until
    `next_due_ns()`), which publishes everything due. In lockstep, `now_ns` is simulated time, so runs are
    deterministic. The rate limit counts `estimate_wire_bytes(len(data))` unless `wire_bytes` is passed.
    """

    def __init__(self, pub: _Putter, link: LinkEmulator) -> None:
        self._pub = pub
        self.link = link
        self._queue: DelayQueue[bytes] = DelayQueue()
        self.published = 0

    def put(self, data: bytes | Callable[[int], bytes], now_ns: int, *, wire_bytes: int | None = None
            ) -> int | None:
        """Submit `data` at `now_ns`; returns its delivery time, or None if the link dropped it. `data` may be a
        function of the delivery time that makes the bytes (`wire_bytes` then required): a sender that stamps
        messages with the emulated link's delivery time (lockstep's simulated clock)."""
        if wire_bytes is None:
            assert not callable(data), "a deferred message needs wire_bytes"
            wire_bytes = estimate_wire_bytes(len(data))
        at = self.link.submit(now_ns, wire_bytes)
        if at is None:
            return None
        if callable(data):
            data = data(at)
        if at <= now_ns and not self._queue:
            self._publish(data)
        else:
            self._queue.push(at, data)
        return at

    def poll(self, now_ns: int) -> int:
        """Publish every held message due at `now_ns`; returns how many were published."""
        due = self._queue.pop_due(now_ns)
        for data in due:
            self._publish(data)
        return len(due)

    def next_due_ns(self) -> int | None:
        return self._queue.next_due_ns()

    def republish(self, data: bytes) -> None:
        """Publish `data` again at once, bypassing the emulator (a re-send of a message it already delivered)."""
        self._publish(data)

    @property
    def pending(self) -> int:
        return len(self._queue)

    def _publish(self, data: bytes) -> None:
        self._pub.put(data)
        self.published += 1

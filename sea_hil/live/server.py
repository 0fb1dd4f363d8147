"""The Foxglove WebSocket server of the live view (foxglove-sdk), and its notices to the process that started it.

`LiveServer(cfg, notify)` starts the SDK's server on `cfg.host:cfg.port` (port 0: a free port) in a context of its
own, with one JSON channel per `sea_hil.live.channels` topic; `publish(LiveMessage)` logs a message on its channel
(the SDK drops it when nobody subscribes); `close` ends with `END_MESSAGE` on
`/live/events` and lingers until the clients have unsubscribed. `notify(dict)` receives `{"event": "listening", "url", "port"}` once the
server listens and `{"event": "subscribed", "topic"}` on each subscription (how `--foxglove-wait` learns that a
client is there). Non-finite numbers are sent as null (as recorded, counted in `nonfinite`); messages that cannot
be encoded are counted in `rejected` and logged, never raised.
"""
from __future__ import annotations

import json
import logging
import math
import threading
from collections.abc import Callable
from typing import Any

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener

from sea_hil.config.live import LiveConfig
from sea_hil.errors import SeaHilError
from sea_hil.live.channels import CHANNELS, END_MESSAGE
from sea_hil.live.events import log_message
from sea_hil.live.view import LiveMessage

log = logging.getLogger("sea_hil.live")
Notify = Callable[[dict[str, Any]], None]


class LiveError(SeaHilError):
    """The live view could not be served (port taken, bad host, ...)."""


class _Listener(ServerListener):
    """Counts subscriptions (total and active); the SDK calls it from its own threads."""

    def __init__(self, notify: Notify) -> None:
        self.notify = notify
        self.subscriptions = 0
        self.active = 0
        self.cond = threading.Condition()

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        with self.cond:
            self.subscriptions += 1
            self.active += 1
        self.notify({"event": "subscribed", "topic": channel.topic, "client": client.id})

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:   # also on disconnect
        with self.cond:
            self.active -= 1
            self.cond.notify_all()

    def wait_unsubscribed(self, timeout_s: float) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: self.active <= 0, timeout=timeout_s)


def _finite(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    return obj


class LiveServer:
    def __init__(self, cfg: LiveConfig, notify: Notify = lambda _msg: None, name: str = "sea-hil") -> None:
        self.context = foxglove.Context()
        self.listener = _Listener(notify)
        self.channels = {topic: foxglove.Channel(topic, schema=foxglove.Schema(
            name=name_, encoding="jsonschema", data=json.dumps(schema).encode()), message_encoding="json",
            context=self.context) for topic, (name_, schema) in CHANNELS.items()}
        try:
            self.server = foxglove.start_server(name=name, host=cfg.host, port=cfg.port, context=self.context,
                                                server_listener=self.listener,
                                                message_backlog_size=cfg.backlog_messages)
        except Exception as err:   # the SDK raises its own (Rust-side) error types
            raise LiveError(f"cannot serve the Foxglove live view on {cfg.host}:{cfg.port}: {err}") from err
        self.port = self.server.port
        self.url = f"ws://{cfg.host}:{self.port}"
        self.published = self.rejected = self.nonfinite = self.last_log_time_ns = 0
        notify({"event": "listening", "url": self.url, "port": self.port})
        log.info("Foxglove live view on %s", self.url)

    def publish(self, msg: LiveMessage) -> None:
        ch = self.channels.get(msg.topic)
        try:
            if ch is None:
                raise ValueError(f"unknown live topic {msg.topic!r}")
            try:
                data = json.dumps(msg.message, allow_nan=False).encode()
            except ValueError:   # NaN/inf: null, as in the recording (sea_hil.recorder.meta.encode_payload)
                self.nonfinite += 1
                data = json.dumps(_finite(msg.message), allow_nan=False).encode()
            ch.log(data, log_time=msg.log_time_ns)
            self.published += 1
            self.last_log_time_ns = max(self.last_log_time_ns, msg.log_time_ns)
        except (ValueError, TypeError) as err:   # unknown topic, not JSON-encodable: count, keep serving
            self.rejected += 1
            if self.rejected <= 10:
                log.warning("live message on %s not published: %s", msg.topic, err)

    def counters(self) -> dict[str, int]:
        return {"live_published": self.published, "live_rejected": self.rejected, "live_nonfinite": self.nonfinite,
                "live_subscriptions": self.listener.subscriptions}

    def close(self, linger_s: float = 0.0) -> None:
        """End of session: publish `END_MESSAGE` on /live/events, keep serving until every client has unsubscribed
        or `linger_s` has passed (stopping the SDK's server drops what it still queues for a client), stop."""
        self.publish(LiveMessage("/live/events", self.last_log_time_ns,
                                 log_message(self.last_log_time_ns, "INFO", "sea-hil", END_MESSAGE)))
        if linger_s > 0:
            self.listener.wait_unsubscribed(linger_s)
        for ch in self.channels.values():
            ch.close()
        self.server.stop()

"""The parent's end of the live view's notice pipe: learn the server's address, wait for a first subscriber.

`LiveLink.open()` makes a pipe; the child (the recorder process) gets `write_fd` (`pass_fds`) in its `LiveSpec`;
after starting the child the parent calls `child_started()` (closes its copy of the write end, so a dead child
reads as end of file) and then `wait_for("listening")` / `wait_for("subscribed")`.
"""
from __future__ import annotations

import json
import os
import selectors
import time
from collections.abc import Callable
from typing import Any

from sea_hil.config.live import LiveConfig
from sea_hil.errors import SeaHilError
from sea_hil.live.feed import LiveSpec

STARTUP_TIMEOUT_S = 60.0   # interpreter + SDK import + bind, on a loaded machine


def live_child_argv(live: LiveSpec | None) -> tuple[list[str], LiveLink | None]:
    """(extra argv of the recorder child, the parent's link) for `live` (its `notify_fd` set to the link's), or
    ([], None)."""
    if live is None:
        return [], None
    link = LiveLink.open()
    return [live.model_copy(update={"notify_fd": link.write_fd}).model_dump_json()], link


class LiveLink:
    def __init__(self, read_fd: int, write_fd: int) -> None:
        self.read_fd, self.write_fd = read_fd, write_fd
        self._buf = b""
        self.seen: list[dict[str, Any]] = []

    @classmethod
    def open(cls) -> LiveLink:
        r, w = os.pipe()
        return cls(r, w)

    def child_started(self) -> None:
        if self.write_fd >= 0:
            os.close(self.write_fd)
            self.write_fd = -1

    def wait_for(self, event: str, timeout_s: float) -> dict[str, Any]:
        """The first notice `event` (also one already read); SeaHilError on timeout, on an `error` notice or when
        the child has gone."""
        deadline = time.monotonic() + timeout_s
        while True:
            for msg in self.seen:
                if msg.get("event") == "error":
                    raise SeaHilError(f"live view: {msg.get('message', 'failed')}")
                if msg.get("event") == event:
                    return msg
            left = deadline - time.monotonic()
            if left <= 0:
                raise SeaHilError(f"live view: no {event!r} within {timeout_s:.0f} s")
            if not self._read(left):
                raise SeaHilError(f"live view: the recorder process ended before {event!r}")

    def _read(self, timeout_s: float) -> bool:
        with selectors.DefaultSelector() as sel:
            sel.register(self.read_fd, selectors.EVENT_READ)
            if not sel.select(timeout_s):
                return True
        chunk = os.read(self.read_fd, 65536)
        if not chunk:
            return False
        self._buf += chunk
        *lines, self._buf = self._buf.split(b"\n")
        for line in lines:
            try:
                msg = json.loads(line)
            except ValueError:
                continue
            if isinstance(msg, dict):
                self.seen.append(msg)
        return True

    def close(self) -> None:
        self.child_started()
        if self.read_fd >= 0:
            os.close(self.read_fd)
            self.read_fd = -1


def await_live(link: LiveLink, cfg: LiveConfig, log: Callable[[str], None]) -> float:
    """Announce the live view's address (`log`) and, with `cfg.wait`, hold until a client has subscribed; -> the
    seconds spent here. SeaHilError when the server did not start or no client came within `wait_timeout_s`."""
    t0 = time.monotonic()
    info = link.wait_for("listening", STARTUP_TIMEOUT_S)
    log(f"Foxglove live view: {info['url']} (open it in Foxglove; layout docs/foxglove/sea-hil-layout.json)")
    if cfg.wait:
        log(f"waiting up to {cfg.wait_timeout_s:.0f} s for a Foxglove client to subscribe ...")
        sub = link.wait_for("subscribed", cfg.wait_timeout_s)
        log(f"Foxglove client subscribed ({sub.get('topic')}); starting")
    return time.monotonic() - t0

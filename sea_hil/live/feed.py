"""The live view inside the recorder: `LiveFeed` = `LiveView` (pure) + `LiveServer` (I/O).

The recorder process calls `feed(topic, log_time_ns, payload)` for every message it has written (the same values),
then `close()`. A message the view cannot digest is counted in `errors` and logged; the recording never suffers.
`LiveSpec` is what the parent hands its recorder child on the command line: the live config, the CAN bitrate
(bus load), what the running verdict needs (the session's `[verdict]` thresholds, whether it runs in lockstep, the
host floor measured at start-up, the limbs' names) and the file descriptor the child reports on (`sea_hil.live.link`).
"""
from __future__ import annotations

import json
import logging
import os
import signal
from typing import Any

from pydantic import BaseModel, ConfigDict

from sea_hil.config.live import LiveConfig
from sea_hil.config.verdict import VerdictConfig
from sea_hil.errors import SeaHilError
from sea_hil.live.server import LiveServer, Notify
from sea_hil.live.view import LiveView

log = logging.getLogger("sea_hil.live")


class LiveSpec(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")
    live: LiveConfig
    bitrate_bps: int
    verdict: VerdictConfig
    lockstep: bool
    floor: dict[str, float] | None = None   # real time: the host's empty-loop floor (sea_hil/runtime/timer_floor.py)
    limbs: dict[int, str] = {}              # node id -> limb name, in the session's order (`sea-hil.limbs`)
    notify_fd: int | None = None


def fd_notifier(fd: int | None) -> Notify:
    """Notices as JSON lines on `fd` (a pipe to the parent); nothing when `fd` is None or the parent is gone."""
    if fd is not None:
        os.set_blocking(fd, False)   # a parent that does not read must never block the SDK's threads

    def notify(msg: dict[str, Any]) -> None:
        if fd is None:
            return
        try:
            os.write(fd, (json.dumps(msg) + "\n").encode())
        except OSError:   # the parent stopped listening (or its pipe is full): the server keeps serving
            pass
    return notify


class LiveFeed:
    def __init__(self, spec: LiveSpec, notify: Notify | None = None) -> None:
        self.spec = spec
        self.view = LiveView(bitrate_bps=spec.bitrate_bps, period_s=spec.live.period_s, window_s=spec.live.window_s,
                             verdict=spec.verdict, lockstep=spec.lockstep, floor=spec.floor,
                             limbs=spec.limbs)
        self.server = LiveServer(spec.live, notify or fd_notifier(spec.notify_fd))
        self.errors = 0

    def feed(self, topic: str, log_time_ns: int, payload: dict[str, Any]) -> None:
        try:
            for msg in self.view.feed(topic, log_time_ns, payload):
                self.server.publish(msg)
        except (TypeError, ValueError, KeyError, AttributeError) as err:   # a malformed message: count, go on
            self.errors += 1
            if self.errors <= 10:
                log.warning("live view ignored a %s message: %s: %s", topic, type(err).__name__, err)

    def counters(self) -> dict[str, int]:
        return {**self.server.counters(), "live_errors": self.errors, "live_ignored": self.view.ignored}

    def close(self) -> None:
        for msg in self.view.finish():
            self.server.publish(msg)
        self.server.close(self.spec.live.linger_s)


def start_live_feed(live_json: str) -> LiveFeed | None:
    """The recorder child's live view from its `LiveSpec` argument, or None. A server that cannot start is reported
    to the parent (which stops the session before it begins) while the recording goes on."""
    # its parent ends this process (CLOSE or end of stdin); Ctrl-C in a terminal reaches the whole process group and
    # must not cut the recording and the live view short
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    spec = LiveSpec.model_validate_json(live_json)
    try:
        return LiveFeed(spec)
    except SeaHilError as err:
        log.error("%s", err)
        fd_notifier(spec.notify_fd)({"event": "error", "message": str(err)})
        return None

"""`sea-hil edge --foxglove` / `controller --foxglove`: the live view of a node started on its own.

The node does not serve it itself (its loops keep their CPU): it starts a `sea-hil record --foxglove ...` child that
joins the node's Zenoh network as a Zenoh client (of the node's `--listen` endpoints, wildcard addresses replaced
by loopback, or of what the node connects to), taps the node's CAN bus when it can be shared between processes (not `virtual:`), records
to `--foxglove-record FILE` or nowhere, and serves from its SCHED_IDLE recorder process. `LiveChild.ready()` echoes
the child's address line and, with `--foxglove-wait`, returns only once a client has subscribed.
"""
from __future__ import annotations

import argparse
import atexit
import ctypes
import os
import queue
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from typing import IO, Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError, SeaHilError
from sea_hil.runtime.processes import end_process

PR_SET_PDEATHSIG = 1
PARENT_ENV = "SEA_HIL_LIVE_PARENT_PID"
_WILDCARDS = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]"}


def reachable(endpoint: str) -> str:
    """An endpoint this host can connect to: a listen endpoint's wildcard address becomes loopback."""
    proto, _, addr = endpoint.partition("/")
    host, sep, port = addr.rpartition(":")
    return f"{proto}/{_WILDCARDS.get(host, host)}{sep}{port}"


def record_cmd(args: argparse.Namespace, cfg: SeaHilConfig, can_spec: str | None) -> list[str]:
    """The `sea-hil record` command line serving this node's live view."""
    # a Zenoh client uses one of its endpoints: the node itself first (it sees everything it exchanges)
    endpoints = [*(reachable(e) for e in cfg.zenoh.listen), *cfg.zenoh.connect]
    if not endpoints:
        raise ConfigError("--foxglove on a node needs --connect or --listen (the live view joins over Zenoh)")
    cmd = [sys.executable, "-m", "sea_hil.cli", "record", "--foxglove", str(cfg.live.port), "--foxglove-host",
           cfg.live.host, *(["--foxglove-wait"] if cfg.live.wait else []), "--limb", cfg.zenoh.limb]
    for e in endpoints:
        cmd += ["--connect", e]
    if can_spec is not None and not can_spec.startswith("virtual:"):
        cmd += ["--can", can_spec]
    if getattr(args, "config", None):
        cmd += ["--config", args.config]
    if getattr(args, "foxglove_record", None):
        cmd += ["--out", str(args.foxglove_record)]
    return cmd


class LiveChild:
    def __init__(self, cmd: list[str], echo: Callable[[str], None]) -> None:
        env = {**os.environ, PARENT_ENV: str(os.getpid())}
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._echo = echo
        self._reader = threading.Thread(target=self._read, args=(self.proc.stderr,), name="live-child", daemon=True)
        self._reader.start()

    def _read(self, stream: IO[bytes]) -> None:
        for raw in iter(stream.readline, b""):
            line = raw.decode(errors="replace").rstrip("\n")
            self._echo(line)
            self._lines.put(line)
        self._lines.put(None)

    def ready(self, wait: bool, timeout_s: float) -> None:
        """Until the child serves (and, with `wait`, a client has subscribed); SeaHilError if it ends first."""
        want = "Foxglove client subscribed" if wait else "Foxglove live view:"
        while True:
            try:
                line = self._lines.get(timeout=timeout_s)
            except queue.Empty:
                raise SeaHilError(f"live view: no {want!r} within {timeout_s:.0f} s") from None
            if line is None:
                raise SeaHilError(f"live view: `sea-hil record` ended with status {self.proc.wait()}")
            if want in line:
                return

    def close(self) -> None:
        end_process(self.proc)   # SIGTERM: the recorder finalises its file and stops serving
        self._reader.join(timeout=5)


def live_child_overrides() -> dict[str, Any]:
    """In `sea-hil record`: when a node started it (`LiveChild`), the config overrides of its role — Zenoh client mode
    (the peer it connects to then forwards it everything it sees: a peer forwards nothing to another peer) — and a
    SIGTERM when the node dies, even by SIGKILL (Linux prctl PR_SET_PDEATHSIG); {} otherwise."""
    parent = os.environ.pop(PARENT_ENV, None)
    if parent is None:
        return {}
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):   # not Linux: the node's atexit ends it
        pass
    if str(os.getppid()) != parent:   # the node is already gone
        raise SystemExit(0)
    return {"zenoh": {"mode": "client"}}


def start_live_child(args: argparse.Namespace, cfg: SeaHilConfig, can_spec: str | None) -> LiveChild | None:
    """The node's live view child when `cfg.live.enabled`, ready (and waited for) and ended when this process
    exits — else None. Start it once the node's Zenoh session is open (it may be what the child connects to)."""
    if not cfg.live.enabled:
        return None

    def echo(s: str) -> None:
        print(s, file=sys.stderr, flush=True)

    if can_spec is not None and can_spec.startswith("virtual:"):
        echo(f"live view: the CAN bus {can_spec} exists in this process only; bus load and driver state not shown")
    child = LiveChild(record_cmd(args, cfg, can_spec), echo)
    try:
        child.ready(cfg.live.wait, cfg.live.wait_timeout_s + 60.0)
    except BaseException:
        child.close()
        raise
    atexit.register(child.close)
    return child


def attach_live_child(builder: Any, args: argparse.Namespace, cfg: SeaHilConfig, can_spec: str | None) -> None:
    """`start_live_child` for a node composed by `builder` (`sea_hil.session.builder.SessionBuilder`): the child is
    ended with the builder's other resources. Call it once the node's Zenoh session is open."""
    child = start_live_child(args, cfg, can_spec)
    if child is not None:
        builder.callback(child.close)

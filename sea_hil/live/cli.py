"""The `--foxglove*` options of `run`, `record`, `edge` and `controller`, and the config overrides they make."""
from __future__ import annotations

import argparse
from typing import Any

CONFIG_PORT = -1   # `--foxglove` without a port: the config's port ([live] port, 8765 by default)


def _port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"port must be an integer, got {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be 0..65535 (0 = any free port), got {port}")
    return port


def add_live_args(p: argparse.ArgumentParser, *, node: bool = False) -> None:
    """The options; `node` (edge, controller): also `--foxglove-record`, the file of the serving recorder."""
    g = p.add_argument_group("live view (Foxglove WebSocket; docs/foxglove/)")
    g.add_argument("--foxglove", nargs="?", type=_port, const=CONFIG_PORT, default=None, metavar="PORT",
                   help="serve the session live over the Foxglove WebSocket protocol (default port 8765; 0 = a "
                        "free port, printed)")
    g.add_argument("--foxglove-host", metavar="HOST",
                   help="interface the live view listens on (default 127.0.0.1: this machine only)")
    g.add_argument("--foxglove-wait", action="store_true",
                   help="start the session only once a Foxglove client has subscribed")
    if node:
        g.add_argument("--foxglove-record", metavar="FILE.mcap",
                       help="the live view is served by a `sea-hil record` child: also keep its recording here")


def live_overrides(args: argparse.Namespace, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """`overrides` plus the `[live]` section the options ask for (any --foxglove* option enables the view)."""
    out: dict[str, Any] = dict(overrides or {})
    live: dict[str, Any] = {}
    if args.foxglove is not None:
        live["enabled"] = True
        if args.foxglove != CONFIG_PORT:
            live["port"] = args.foxglove
    if args.foxglove_host:
        live.update(enabled=True, host=args.foxglove_host)
    if args.foxglove_wait:
        live.update(enabled=True, wait=True)
    if live:
        out["live"] = {**out.get("live", {}), **live}
    return out

"""`sea-hil router`: a Zenoh router in this process (zenoh-python's router mode), for the router topology where
neither zenohd nor the `eclipse/zenoh` image (docker-compose.yml) is at hand. Every node connects to it in client
mode (`--mode client` or configs/session.toml); it runs until SIGINT/SIGTERM (docs/topologies.md)."""
from __future__ import annotations

import argparse
import signal
import sys
import threading

from sea_hil.protocol.zsession import make_config, open_session


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("router", help="a Zenoh router (zenoh-python router mode) for the nodes to connect to",
                       description="Route every key between the sessions connected to it, until SIGINT/SIGTERM. "
                                   "Multicast scouting off, like every sea-hil session.")
    p.add_argument("--listen", action="append", required=True, metavar="ENDPOINT",
                   help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="another router to connect to (repeatable)")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = open_session(make_config(mode="router", listen=args.listen, connect=args.connect))
    try:
        print(f"sea-hil router: listening on {', '.join(args.listen)}", file=sys.stderr, flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        session.close()
    return 0

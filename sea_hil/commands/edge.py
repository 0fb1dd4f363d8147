"""`sea-hil edge`: the CAN<->Zenoh bridge with the inner loop, on its own."""
from __future__ import annotations

import argparse
import signal

from sea_hil.commands.node_cli import add_node_args, node_session, print_result, raise_node


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("edge", help="edge node: CAN<->Zenoh bridge running the backstepping inner loop")
    p.add_argument("--can", metavar="SPEC", help="socketcan:vcan0 | virtual:NAME | ipc:NAME | udp_multicast:GROUP")
    p.add_argument("--node", type=int, default=1, help="driver node id")
    p.add_argument("--controller", choices=("tt", "et"), default="et",
                   help="the trigger the edge runs with --trigger edge (the controller's mode)")
    add_node_args(p, link=True)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    with node_session(args, "edge") as (b, cfg, session):
        node = b.edge(b.bus(), session, args.node, inner=args.inner, mode=args.controller)
        raise_node(args, node, cfg, "edge")
        b.serve(node, signals=(signal.SIGINT, signal.SIGTERM))   # Ctrl-C too: final stats, then the result
        counters = node.stats_dict()
    print_result(args, "edge", counters, True)
    return 0

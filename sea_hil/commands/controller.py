"""`sea-hil controller`: the remote ET/TT SMC node on its own."""
from __future__ import annotations

import argparse
import signal

from sea_hil.commands.node_cli import add_node_args, node_session, print_result


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("controller", help="remote controller node (ET/TT SMC over Zenoh)",
                       description="Subscribe to the limb state, run the outer SMC and publish setpoints only on "
                                   "events (TT: every sample). Exits after --cycles walking cycles.")
    p.add_argument("--controller", choices=("tt", "et"), default="et")
    p.add_argument("--cycles", type=int, default=1)
    p.add_argument("--timeout", type=float, default=None, help="give up after this many seconds without finishing")
    p.add_argument("--await-recorder", type=float, default=0.0, metavar="S",
                   help="a recorder is expected: before the first tracking record, wait up to S s for a subscriber "
                        "of the event key (a recorder joining across a slow link); default 0: no wait")
    add_node_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    with node_session(args, "controller") as (b, _cfg, session):
        node = b.controller(session, args.controller, inner=args.inner, cycles=args.cycles)
        node.await_recorder_s = args.await_recorder
        done = b.serve(node, args.timeout, signals=(signal.SIGINT, signal.SIGTERM))
        counters = node.stats_dict()
    print_result(args, "controller", counters, done)
    return 0 if done else 3

"""`sea-hil edge`: the CAN<->Zenoh bridge with the inner loop, on its own."""
from __future__ import annotations

import argparse

from sea_hil.commands.common import (add_config_args, add_link_args, add_scheme_args, add_zenoh_args,
                                     config_from_args)
from sea_hil.live.cli import add_live_args, live_overrides


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("edge", help="edge node: CAN<->Zenoh bridge running the backstepping inner loop")
    p.add_argument("--can", metavar="SPEC", help="socketcan:vcan0 | virtual:NAME | udp_multicast:GROUP")
    p.add_argument("--node", type=int, default=1, help="driver node id")
    p.add_argument("--inner", choices=("edge", "remote"), default="edge")
    p.add_argument("--lockstep", action="store_true")
    p.add_argument("--controller", choices=("tt", "et"), default="et",
                   help="the trigger the edge runs with --trigger edge (the controller's mode)")
    add_zenoh_args(p)
    add_link_args(p)
    add_live_args(p, node=True)
    add_config_args(p)
    add_scheme_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    from sea_hil.live.child import attach_live_child
    from sea_hil.runtime.realtime import raise_node_process
    from sea_hil.session.builder import SessionBuilder
    cfg = config_from_args(args, live_overrides(args))
    with SessionBuilder(cfg, lockstep=args.lockstep) as b:
        session = b.zenoh()
        attach_live_child(b, args, cfg, cfg.can.interface)   # --foxglove: a `sea-hil record` child serves the live view
        node = b.edge(b.bus(), session, args.node, inner=args.inner, mode=args.controller)
        if not args.lockstep:   # a process of its own (the compose topology): [timing] SCHED_FIFO, one below the driver
            raise_node_process(node, cfg.timing, "edge")
        b.serve(node)
    return 0

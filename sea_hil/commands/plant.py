"""`sea-hil plant`: the emulated SEA driver node on its own."""
from __future__ import annotations

import argparse

from sea_hil.commands.common import add_config_args, config_from_args
from sea_hil.session.builder import SessionBuilder


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plant", help="emulated SEA motor driver node on a CAN bus",
                       description="Integrate the limb model in real time and answer CAN voltage frames like drive "
                                   "firmware: feedback at --rate, heartbeat, watchdog, e-stop, clear-errors.")
    p.add_argument("--can", metavar="SPEC", help="socketcan:vcan0 | virtual:NAME | udp_multicast:GROUP "
                                                 "(default from config)")
    p.add_argument("--node", type=int, action="append", help="node id served (repeatable for several limbs)")
    p.add_argument("--rate", type=float, help="feedback rate in Hz (default 1000)")
    p.add_argument("--watchdog", type=float, metavar="SECONDS", help="command watchdog timeout (default 0.1)")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (default: until SIGINT)")
    p.add_argument("--lockstep", action="store_true", help="advance one sample per answered feedback")
    add_config_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    can_ov = {k: v for k, v in (("feedback_rate_hz", args.rate), ("watchdog_timeout_s", args.watchdog))
              if v is not None}
    cfg = config_from_args(args, {"can": can_ov} if can_ov else None)
    with SessionBuilder(cfg, lockstep=args.lockstep) as b:
        node = b.plant(b.bus(), tuple(args.node or cfg.can.node_ids))
        b.serve(node, args.duration)
    print(f"ticks {node.stats.ticks} overruns {node.stats.overruns} "
          f"lateness p99 {node.lateness.percentile(99) * 1e6:.0f} us")
    return 0

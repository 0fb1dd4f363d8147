"""`sea-hil controller`: the remote ET/TT SMC node on its own."""
from __future__ import annotations

import argparse

from sea_hil.commands.common import add_config_args, add_scheme_args, add_zenoh_args, config_from_args
from sea_hil.live.cli import add_live_args, live_overrides


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("controller", help="remote controller node (ET/TT SMC over Zenoh)",
                       description="Subscribe to the limb state, run the outer SMC and publish setpoints only on "
                                   "events (TT: every sample). Exits after --cycles walking cycles.")
    p.add_argument("--controller", choices=("tt", "et"), default="et")
    p.add_argument("--cycles", type=int, default=1)
    p.add_argument("--inner", choices=("edge", "remote"), default="edge")
    p.add_argument("--lockstep", action="store_true")
    p.add_argument("--timeout", type=float, default=None, help="give up after this many seconds without finishing")
    add_zenoh_args(p)
    add_live_args(p, node=True)
    add_config_args(p)
    add_scheme_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    from sea_hil.live.child import attach_live_child
    from sea_hil.runtime.realtime import node_priority
    from sea_hil.session.builder import SessionBuilder
    cfg = config_from_args(args, live_overrides(args))
    priority = node_priority(cfg.timing, "controller")
    if not args.lockstep and not cfg.timing.controller_priority and priority:
        # a process of its own (the compose topology; `sea-hil run` sets it for its children): SCHED_FIFO two below
        # the driver, taken after the start-up (`RealTimeControllerSync.state_source`)
        cfg = cfg.model_copy(update={"timing": cfg.timing.model_copy(update={"controller_priority": priority})})
    with SessionBuilder(cfg, lockstep=args.lockstep) as b:
        session = b.zenoh()
        attach_live_child(b, args, cfg, None)   # --foxglove: a `sea-hil record` child serves the live view
        node = b.controller(session, args.controller, inner=args.inner, cycles=args.cycles)
        done = b.serve(node, args.timeout)
    return 0 if done else 3

"""`sea-hil run`: one command, a full HIL session on this machine."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sea_hil.commands.common import (
    add_config_args,
    add_link_args,
    add_period_arg,
    add_scenario_args,
    add_scheme_args,
    add_strict_arg,
    config_from_args,
)
from sea_hil.errors import ConfigError
from sea_hil.live.cli import add_live_args, live_overrides
from sea_hil.report.console import SessionProgress, files_in, print_end_of_run
from sea_hil.session.run import RunOptions, print_summary, run_session
from sea_hil.verdict.rules import strict_status


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="full session: plant + edge + recorder here, remote controller over Zenoh",
                       description="Start plant and edge on the CAN bus (embedded virtual bus by default), the "
                                   "remote controller in a separate process over Zenoh, and the MCAP recorder; run "
                                   "N walking cycles; write DIR/session.mcap, DIR/summary.json and figures.")
    p.add_argument("--controller", choices=("tt", "et", "external"), default="et",
                   help="external: start no controller, wait for one from outside (docs/external-controller.md)")
    p.add_argument("--join-timeout", type=float, default=300.0, metavar="S",
                   help="--controller external: seconds to wait for the outside controller's first answer")
    p.add_argument("--cycles", type=int, default=1, help="walking cycles (10 s each by default)")
    p.add_argument("--out", type=Path, default=Path("runs/latest"), metavar="DIR")
    p.add_argument("--lockstep", action="store_true", help="advance simulated time only when every node has handled "
                                                            "the step (deterministic, as fast as possible)")
    p.add_argument("--inner", choices=("edge", "remote"), default="edge",
                   help="where the backstepping voltage loop runs (edge = next to CAN at 1 kHz; remote = in the "
                        "controller at the 10 ms sample rate, voltages tunnelled to CAN)")
    p.add_argument("--can", metavar="SPEC", help="CAN bus: virtual:NAME (default), socketcan:vcan0, ipc:NAME, udp_multicast:GROUP")
    p.add_argument("--node", type=int, default=1, help="driver node id (of the first limb)")
    p.add_argument("--can-profile", choices=("sea", "cia402"), help="sea = the DBC protocol; cia402 = CANopen "
                   "CiA 402, the edge as the master of the limb's two nodes (--lockstep only; docs/cia402.md); "
                   "default [can] profile")
    p.add_argument("--limbs", type=int, default=None, metavar="N",
                   help="emulate the default limb N times (node ids --node.., limb1..limbN), over as many CAN buses "
                        "as the bus-load model needs (docs/session.md, 'Several limbs'); default: [[limbs]] or 1")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help="Zenoh endpoint this process listens on (default: a free loopback port)")
    p.add_argument("--secure", action="store_true",
                   help="mutual TLS + access control on every Zenoh link: this process presents the edge's "
                        "certificate, the controller child the controller's (docs/security.md)")
    p.add_argument("--certs", type=Path, metavar="DIR",
                   help="--secure with the certificates of `sea-hil certs --out DIR` (default: generated into "
                        "OUT/certs); implies --secure")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--no-figures", dest="figures", action="store_false",
                   help="write no PNG figures (about 1 s a session; `sea-hil report DIR` draws them from the "
                        "recording later): a sweep's points run with it")
    p.add_argument("--json", action="store_true", help="print summary.json instead of the end-of-run table")
    p.add_argument("--driver-process", action=argparse.BooleanOptionalAction, default=None,
                   help="real time: each CAN driver in a process of its own, on an ipc bus in place of the embedded "
                        "virtual one (no GIL shared with the edge; docs/timing.md); default [timing] driver_process, else "
                        "by profile (cia402 yes, sea no)")
    add_strict_arg(p)
    add_link_args(p)
    add_live_args(p)
    add_config_args(p)
    add_period_arg(p)
    add_scheme_args(p)
    add_scenario_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if args.cycles < 1:
        raise ConfigError("--cycles must be >= 1")
    overrides = live_overrides(args)
    if args.can_profile:
        overrides = {**(overrides or {}), "can": {**(overrides or {}).get("can", {}), "profile": args.can_profile}}
    cfg = config_from_args(args, overrides, check="session")
    opts = RunOptions(controller=args.controller, cycles=args.cycles, out=args.out, lockstep=args.lockstep,
                      inner=args.inner, can=args.can, node_id=args.node, limbs=args.limbs, listen=tuple(args.listen),
                      progress=not args.quiet, seed=args.seed,
                      join_timeout_s=args.join_timeout, secure=args.secure or args.certs is not None,
                      certs=args.certs, figures=args.figures, driver_process=args.driver_process)
    with SessionProgress(sys.stderr) as progress:
        summary = run_session(cfg, opts, log=progress)
    if args.json:
        print_summary(summary)
    else:
        # TT publishes and answers a state at every sample of the cycle, both ends included
        samples = round(summary["duration_s"] / cfg.controller.sample_period_s) + 1
        print_end_of_run(summary, files_in(args.out), tt_msgs=samples)
    return strict_status(summary) if args.strict else 0

"""`sea-hil plant`: the emulated SEA driver node on its own."""
from __future__ import annotations

import argparse

from sea_hil.commands.common import add_config_args, config_from_args
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError
from sea_hil.plant_emulator.cia402_node import Cia402PlantNode
from sea_hil.protocol.cia402_eds import eds_path
from sea_hil.session.builder import SessionBuilder


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plant", help="emulated SEA motor driver node on a CAN bus",
                       description="Integrate the limb model in real time and answer CAN voltage frames like drive "
                                   "firmware: feedback at --rate, heartbeat, watchdog, e-stop, clear-errors.")
    p.add_argument("--can", metavar="SPEC", help="socketcan:vcan0 | virtual:NAME | ipc:NAME | udp_multicast:GROUP "
                                                 "(default from config)")
    p.add_argument("--node", type=int, action="append", help="node id served (repeatable for several limbs; with "
                                                              "--can-profile cia402: hip and knee id per limb)")
    p.add_argument("--can-profile", choices=("sea", "cia402"), help="sea = the DBC protocol; cia402 = CANopen "
                   "CiA 301/402, each SEA its own node, EDS in the package (docs/cia402.md); default [can] profile")
    p.add_argument("--rate", type=float, help="feedback rate in Hz (default 1000)")
    p.add_argument("--watchdog", type=float, metavar="SECONDS", help="command watchdog timeout (default 0.1)")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (default: until SIGINT)")
    p.add_argument("--lockstep", action="store_true", help="advance one sample per answered feedback")
    add_config_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    can_ov = {k: v for k, v in (("feedback_rate_hz", args.rate), ("watchdog_timeout_s", args.watchdog))
              if v is not None}
    if args.can_profile:
        can_ov["profile"] = args.can_profile
    cfg = config_from_args(args, {"can": can_ov} if can_ov else None)
    if cfg.can.profile == "cia402":
        return _cia402(cfg, args)
    with SessionBuilder(cfg, lockstep=args.lockstep) as b:
        node = b.plant(b.bus(), tuple(args.node or cfg.can.node_ids))
        b.serve(node, args.duration)
    print(f"ticks {node.stats.ticks} overruns {node.stats.overruns} "
          f"lateness p99 {node.lateness.percentile(99) * 1e6:.0f} us")
    return 0


def _cia402(cfg: SeaHilConfig, args: argparse.Namespace) -> int:
    """The CiA 402 drive alone (real time; a lab's CANopen master, e.g. python canopen or ros2_canopen, connects)."""
    if args.lockstep:
        raise ConfigError("--lockstep is not available with --can-profile cia402 (the master's SYNC paces it)")
    node_ids = tuple(args.node) if args.node else cfg.can.cia402.node_ids
    with SessionBuilder(cfg) as b:
        node = Cia402PlantNode(cfg, b.bus(args.can), node_ids)
        print(f"cia402 drive on {args.can or cfg.can.interface}: node ids {node_ids} (hip, knee per limb); "
              f"EDS {eds_path('hip')}, {eds_path('knee')}", flush=True)
        b.serve(node, args.duration)
    print(" ".join(f"{k} {int(v)}" for k, v in node._stats().items()))
    return 0

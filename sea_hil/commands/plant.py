"""`sea-hil plant`: the emulated SEA driver node on its own (also `sea-hil run`'s driver process, `[timing]
driver_process`: `--hold`, `--json`; sea_hil/session/driver_process.py)."""
from __future__ import annotations

import argparse
import sys
from typing import Any

from sea_hil.commands.common import add_config_args, config_from_args
from sea_hil.commands.node_cli import add_json_arg, print_result
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError
from sea_hil.plant_emulator.cia402_node import Cia402PlantNode
from sea_hil.protocol.cia402_eds import eds_path
from sea_hil.protocol.merged_bus import MergedBus
from sea_hil.session.builder import SessionBuilder


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plant", help="emulated SEA motor driver node on a CAN bus",
                       description="Integrate the limb model in real time and answer CAN voltage frames like drive "
                                   "firmware: feedback at --rate, heartbeat, watchdog, e-stop, clear-errors.")
    p.add_argument("--can", dest="cans", action="append", metavar="SPEC",
                   help="socketcan:vcan0 | virtual:NAME | ipc:NAME | udp_multicast:GROUP (default from config); "
                        "given once per --node: each node on its own bus, all served by one driver thread (one "
                        "merged bus, as `sea-hil run` with [timing] merge_buses)")
    p.add_argument("--node", type=int, action="append", help="node id served (repeatable for several limbs; with "
                                                              "--can-profile cia402: hip and knee id per limb)")
    p.add_argument("--can-profile", choices=("sea", "cia402"), help="sea = the DBC protocol; cia402 = CANopen "
                   "CiA 301/402, each SEA its own node, EDS in the package (docs/cia402.md); default [can] profile")
    p.add_argument("--rate", type=float, help="feedback rate in Hz (default 1000)")
    p.add_argument("--watchdog", type=float, metavar="SECONDS", help="command watchdog timeout (default 0.1)")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (default: until SIGINT)")
    p.add_argument("--lockstep", action="store_true", help="advance one sample per answered feedback")
    p.add_argument("--hold", action="store_true",
                   help="open the bus and load the kernels, then start the schedule only when a line arrives on "
                        "stdin (end of stdin first: exit at once); `sea-hil run`'s driver process")
    add_config_args(p)
    add_json_arg(p)
    p.set_defaults(func=_main)


def bus_routes(cans: list[str], node_ids: tuple[int, ...]) -> dict[int, str] | None:
    """node id -> its bus spec when several `--can` are given (one per `--node`, in order), None for one bus;
    `ConfigError` when the counts differ."""
    if len(cans) <= 1:
        return None
    if len(cans) != len(node_ids):
        raise ConfigError(f"--can given {len(cans)} times for {len(node_ids)} node id(s): give one --can per --node "
                          "(or one --can for all)")
    return dict(zip(node_ids, cans, strict=True))


def _open_bus(b: SessionBuilder, cans: list[str], node_ids: tuple[int, ...]) -> Any:
    """The driver's handle: one bus, or a `MergedBus` over one handle per distinct spec."""
    routes = bus_routes(cans, node_ids)
    if routes is None:
        return b.bus(cans[0] if cans else None)
    handles = {spec: b.bus(spec) for spec in dict.fromkeys(routes.values())}
    return MergedBus({n: handles[spec] for n, spec in routes.items()})


def _hold(args: argparse.Namespace) -> bool:
    """With `--hold`: wait for the go line on stdin; False when stdin ended first (the parent is gone)."""
    return not args.hold or bool(sys.stdin.readline())


def _main(args: argparse.Namespace) -> int:
    can_ov: dict[str, Any] = {k: v for k, v in (("feedback_rate_hz", args.rate), ("watchdog_timeout_s", args.watchdog))
                              if v is not None}
    if args.can_profile:
        can_ov["profile"] = args.can_profile
    cans = list(args.cans or ())
    if cans:
        can_ov["interface"] = cans[0]
    cfg = config_from_args(args, {"can": can_ov} if can_ov else None)
    if cfg.can.profile == "cia402":
        return _cia402(cfg, args)
    node_ids = tuple(args.node or cfg.can.node_ids)
    with SessionBuilder(cfg, lockstep=args.lockstep) as b:
        node = b.plant(_open_bus(b, cans, node_ids), node_ids)
        if not _hold(args):
            return 0
        b.serve(node, args.duration)
    if args.json or args.no_result:
        print_result(args, "plant", node.stats_dict(), True)
    else:
        print(f"ticks {node.stats.ticks} overruns {node.stats.overruns} "
              f"lateness p99 {node.lateness.percentile(99) * 1e6:.0f} us")
    return 0


def _cia402(cfg: SeaHilConfig, args: argparse.Namespace) -> int:
    """The CiA 402 drive alone (real time; a lab's CANopen master, e.g. python canopen or ros2_canopen, connects)."""
    if args.lockstep:
        raise ConfigError("--lockstep is not available with --can-profile cia402 (the master's SYNC paces it)")
    if args.cans and len(args.cans) > 1:
        raise ConfigError("--can-profile cia402: one bus per drive process (its master is that bus's SYNC producer)")
    node_ids = tuple(args.node) if args.node else cfg.can.cia402.node_ids
    with SessionBuilder(cfg) as b:
        node = Cia402PlantNode(cfg, b.bus(), node_ids)
        if not args.json:
            print(f"cia402 drive on {cfg.can.interface}: node ids {node_ids} (hip, knee per limb); "
                  f"EDS {eds_path('hip')}, {eds_path('knee')}", flush=True)
        if not _hold(args):
            return 0
        b.serve(node, args.duration)
    counters = {**node.stats_dict(), "ticks": node.stats.ticks, "overruns": node.stats.overruns}
    if args.json or args.no_result:
        print_result(args, "plant", counters, True)
    else:
        print(" ".join(f"{k} {int(v)}" for k, v in node._stats().items()))
    return 0

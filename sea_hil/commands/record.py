"""`sea-hil record`: the recorder node on its own (Zenoh, and CAN if --can is given)."""
from __future__ import annotations

import argparse
import signal
from pathlib import Path

from sea_hil.commands.common import add_config_args, add_zenoh_args, config_from_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record every Zenoh message (and CAN frame) of a session to MCAP")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.mcap")
    p.add_argument("--can", metavar="SPEC", help="also record this CAN bus")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (default: SIGINT/SIGTERM)")
    add_zenoh_args(p)
    add_config_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    import sys
    from sea_hil.recorder.writer import SessionRecorder
    from sea_hil.session.builder import SessionBuilder
    cfg = config_from_args(args)
    with SessionBuilder(cfg) as b:
        session = b.zenoh()
        bus = b.bus(args.can) if args.can else None
        rec = SessionRecorder.from_config(args.out, cfg.record)
        rec.write_session_header(cfg, seed=cfg.link.seed, argv=sys.argv)
        node = b.recorder(rec, session, bus)
        b.callback(lambda: rec.close(final_stats=node.counters()))   # after the node has stopped its taps
        b.serve(node, args.duration, signals=(signal.SIGINT, signal.SIGTERM))
    return 0

"""`sea-hil record`: the recorder node on its own (Zenoh, and CAN if --can is given)."""
from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path
from typing import Any

from sea_hil.commands.common import add_config_args, add_zenoh_args, config_from_args
from sea_hil.commands.node_cli import add_json_arg
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError
from sea_hil.live.child import live_child_overrides
from sea_hil.live.cli import add_live_args, live_overrides
from sea_hil.live.feed import LiveSpec
from sea_hil.live.link import await_live
from sea_hil.recorder.clock import TIME_BASES
from sea_hil.recorder.process import RecorderProcess
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.report.completeness import completeness_block, read_for_completeness
from sea_hil.report.node_summary import node_summary, print_node_summary
from sea_hil.session.builder import SessionBuilder


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record every Zenoh message (and CAN frame) of a session to MCAP")
    p.add_argument("--out", type=Path, metavar="FILE.mcap", help="the recording (optional with --foxglove: live only)")
    p.add_argument("--can", metavar="SPEC", help="also record this CAN bus")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (default: SIGINT/SIGTERM)")
    p.add_argument("--time-base", choices=TIME_BASES, default="wall",
                   help="MCAP log_time clock: wall (default) or the drive's sample time (for lockstep sessions)")
    add_zenoh_args(p)
    add_live_args(p)
    add_config_args(p)
    add_json_arg(p)
    p.set_defaults(func=_main)


def as_observer(cfg: SeaHilConfig, mode: str | None) -> SeaHilConfig:
    """The recorder that only connects (no `--listen`, no `--mode`) joins as a Zenoh client of the node it connects
    to. Two peers forward each other only their own publications, so a recorder peer on the edge's endpoint never
    saw the controller's setpoints (issue 32); a peer routes everything its clients subscribe to (and so does a
    router). docs/topologies.md."""
    z = cfg.zenoh
    if mode is not None or z.mode != "peer" or not z.connect or z.listen:
        return cfg
    return cfg.model_copy(update={"zenoh": z.model_copy(update={"mode": "client"})})


def _main(args: argparse.Namespace) -> int:
    # started by `edge`/`controller --foxglove`: a Zenoh client of that node, ended with it
    child = live_child_overrides()    # the live view of `edge`/`controller --foxglove`: that node prints the result
    cfg = as_observer(config_from_args(args, live_overrides(args, child)), args.mode)
    if args.out is None and not cfg.live.enabled:
        raise ConfigError("record needs --out FILE.mcap (or --foxglove for a live view without a file)")
    out = args.out if args.out is not None else Path(os.devnull)
    with SessionBuilder(cfg) as b:
        session = b.zenoh()
        bus = b.bus(args.can) if args.can else None
        if cfg.live.enabled:   # --foxglove: write and serve from a recorder process on idle CPU time
            rec: RecorderProcess | SessionRecorder
            rec = process = RecorderProcess(out, cfg.record, idle=True, time_base=args.time_base,
                                            live=LiveSpec(live=cfg.live, bitrate_bps=cfg.can.bitrate_bps,
                                                          verdict=cfg.verdict, lockstep=args.time_base == "sample"))
            b.callback(process.close)      # idempotent: closes the file if waiting for the live view failed
            assert process.live is not None   # a live config was passed
            await_live(process.live, cfg.live, lambda s: print(s, file=sys.stderr, flush=True))
        else:
            rec = SessionRecorder.from_config(out, cfg.record)
        rec.write_session_header(cfg, seed=cfg.link.seed, argv=sys.argv)
        node = b.recorder(rec, session, bus, time_base=args.time_base)
        b.callback(lambda: rec.close(final_stats=node.counters()))   # after the node has stopped its taps
        # subscribed: from here on the recorder receives what is routed to it (a topology's start-up waits for it)
        print(f"sea-hil record: recording {cfg.zenoh.prefix}/** to {out}", file=sys.stderr, flush=True)
        b.serve(node, args.duration, signals=(signal.SIGINT, signal.SIGTERM))
        counters = node.counters()
    if not child:
        print_record_result(args, out if args.out is not None else None, counters)
    return 0


def print_record_result(args: argparse.Namespace, out: Path | None, counters: dict[str, Any]) -> None:
    """The recorder's own result: its counters (from the file's final record, the writer's included) and whether
    the file is complete against the nodes' counters (`sea_hil.report.completeness`)."""
    completeness = None
    if out is not None:
        data = read_for_completeness(out)
        final = data.metadata.get("sea-hil.final", {})
        counters = {**counters, **{k: int(v) for k, v in final.items() if v.lstrip("-").isdigit()}}
        completeness = completeness_block(data)
    summary = node_summary("recorder", counters, finished=True, completeness=completeness,
                           recording=None if out is None else str(out))
    print_node_summary(summary, as_json=args.json, command="record")

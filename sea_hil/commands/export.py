"""`sea-hil export`: a session recording to CAN tools (candump log, Vector ASC) and CSV."""
from __future__ import annotations

import argparse
from pathlib import Path

from sea_hil.errors import ConfigError
from sea_hil.recorder.export import export_can, export_csv
from sea_hil.recorder.reader import read_session


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a recording: CAN frames to candump -L / ASC, channels to CSV",
                       description="Export RUN.mcap: every CAN frame of /can/raw as a candump -L log (replay with "
                                   "canplayer -I FILE) and/or a Vector ASC file, and every channel as a CSV with "
                                   "flat columns (docs/recording.md, Export). At least one output is required.")
    p.add_argument("mcap", type=Path, metavar="RUN.mcap")
    p.add_argument("--candump", type=Path, metavar="FILE.log", help="candump -L log of every recorded frame")
    p.add_argument("--asc", type=Path, metavar="FILE.asc", help="Vector ASC log of every recorded frame")
    p.add_argument("--csv", type=Path, metavar="DIR", help="one CSV per channel into DIR")
    p.add_argument("--channel", default="vcan0", help="interface name written in the candump log (default vcan0)")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if not (args.candump or args.asc or args.csv):
        raise ConfigError("nothing to export: give --candump FILE, --asc FILE and/or --csv DIR")
    data = read_session(args.mcap)
    if not data.complete:
        print(f"warning: {args.mcap} is truncated ({data.tail_error}); exporting the {data.message_count} "
              "messages recovered")
    if args.candump:
        print(f"{args.candump}: {export_can(data, args.candump, 'candump', args.channel)} frames (candump -L)")
    if args.asc:
        print(f"{args.asc}: {export_can(data, args.asc, 'asc')} frames (ASC)")
    if args.csv:
        for path in export_csv(data, args.csv):
            print(f"{path}")
    return 0

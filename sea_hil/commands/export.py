"""`sea-hil export`: a session recording to CAN tools (candump log, Vector ASC), CSV and a ROS 2 bag."""
from __future__ import annotations

import argparse
from pathlib import Path

from sea_hil.errors import ConfigError
from sea_hil.recorder.export import canopen_path, export_can, export_canopen, export_csv
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.session_config import canopen_decoder
from sea_hil.ros2.export import export_ros2


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a recording: CAN frames to candump -L / ASC, channels to CSV, "
                                      "the session to a ROS 2 bag",
                       description="Export RUN.mcap: every CAN frame of /can/raw as a candump -L log (replay with "
                                   "canplayer -I FILE) and/or a Vector ASC file, every channel as a CSV with "
                                   "flat columns (docs/recording.md, Export), and/or the session as a rosbag2 "
                                   "directory with standard ROS 2 messages (docs/ros2.md). At least one output is "
                                   "required.")
    p.add_argument("mcap", type=Path, metavar="RUN.mcap")
    p.add_argument("--candump", type=Path, metavar="FILE.log", help="candump -L log of every recorded frame (a "
                   "cia402 session: also FILE.canopen.csv, every frame decoded with the EDS's names)")
    p.add_argument("--asc", type=Path, metavar="FILE.asc", help="Vector ASC log of every recorded frame")
    p.add_argument("--csv", type=Path, metavar="DIR", help="one CSV per channel into DIR")
    p.add_argument("--ros2", type=Path, metavar="DIR",
                   help="a rosbag2 directory DIR (new): metadata.yaml + one MCAP of CDR messages (ros2 bag play DIR)")
    p.add_argument("--channel", default="vcan0", help="interface name written in the candump log (default vcan0)")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if not (args.candump or args.asc or args.csv or args.ros2):
        raise ConfigError("nothing to export: give --candump FILE, --asc FILE, --csv DIR and/or --ros2 DIR")
    if args.ros2:   # first: it refuses a truncated or foreign file before any output is written
        bag = export_ros2(args.mcap, args.ros2)
        print(f"{bag.directory}: rosbag2, {bag.message_count} messages on {len(bag.counts)} topics "
              f"(ros2 bag play {bag.directory})")
        if not (args.candump or args.asc or args.csv):
            return 0
    data = read_session(args.mcap)
    if not data.complete:
        print(f"warning: {args.mcap} is truncated ({data.tail_error}); exporting the {data.message_count} "
              "messages recovered")
    if args.candump:
        print(f"{args.candump}: {export_can(data, args.candump, 'candump', args.channel)} frames (candump -L)")
        decoder = canopen_decoder(data)
        if decoder is not None:   # a cia402 session: the frames' meaning, in the EDS's names, beside the log
            out = canopen_path(args.candump)
            print(f"{out}: {export_canopen(data, out, decoder)} frames decoded (CANopen, the EDS's names)")
    if args.asc:
        print(f"{args.asc}: {export_can(data, args.asc, 'asc')} frames (ASC)")
    if args.csv:
        for path in export_csv(data, args.csv):
            print(f"{path}")
    return 0

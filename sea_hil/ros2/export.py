"""`sea-hil export RUN.mcap --ros2 DIR`: a whole session recording as a rosbag2 directory (docs/ros2.md).

Only a complete sea-hil recording is exported: a truncated file (no footer: a crashed recorder) or an MCAP file
that is not a sea-hil session is refused with a `RecordingError` (one line, exit 2 at the CLI) before anything is
written; repair a crashed file first (`mcap recover`, docs/recording.md "Reading and recovery").
"""
from __future__ import annotations

import os
from pathlib import Path

from sea_hil.errors import RecordingError
from sea_hil.recorder.reader import SessionData, read_session
from sea_hil.recorder.session_config import session_config
from sea_hil.ros2.bag import BagSummary, write_bag
from sea_hil.ros2.convert import Converter

SEA_HIL_MARK = "/can/raw"   # every sea-hil recording registers this channel (sea_hil.recorder.writer)
# its encodings: JSON in recordings before the binary CAN channels, protobuf since (sea_hil.recorder.binary)
SEA_HIL_MARK_ENCODINGS = (("jsonschema", "json"), ("protobuf", "protobuf"))


def check_sea_hil(data: SessionData, path: str | os.PathLike[str]) -> None:
    """`RecordingError` unless `data` is a complete sea-hil recording."""
    if data.encodings.get(SEA_HIL_MARK) not in SEA_HIL_MARK_ENCODINGS:
        raise RecordingError(f"{path} is not a sea-hil recording (no channel {SEA_HIL_MARK})")
    if not data.complete:
        raise RecordingError(f"{path} is truncated ({data.tail_error or 'no footer'}); repair it first "
                             "(`mcap recover`), nothing exported")


def export_ros2(path: str | os.PathLike[str], directory: str | os.PathLike[str]) -> BagSummary:
    """Read the recording at `path`, write the bag directory `directory` (must not exist)."""
    data = read_session(path)
    check_sea_hil(data, path)
    conv = Converter(data, session_config(data))
    lockstep = data.metadata.get("sea-hil.session", {}).get("lockstep") == "True"
    custom = {"sea_hil.source": Path(path).name, "sea_hil.log_time_clock": "sample" if lockstep else "wall",
              "sea_hil.header_stamp_clock": "sample", "sea_hil.limbs": " ".join(conv.limbs.names),
              "sea_hil.version": data.metadata.get("sea-hil.session", {}).get("version.sea-hil", "")}
    return write_bag(conv.messages(), directory, custom)

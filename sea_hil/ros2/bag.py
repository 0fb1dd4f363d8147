"""Writing a rosbag2 directory (`sea-hil export RUN.mcap --ros2 DIR`, docs/ros2.md): `metadata.yaml` plus one
MCAP file of profile `ros2`, `ros2msg` schemas and CDR messages, as rosbag2's MCAP storage plugin writes it.

Encoding is mcap-ros2-support's CDR encoder for the schema text (the one its `mcap_ros2.writer.Writer` uses); the
file is written with the `mcap` writer directly because that `Writer` registers channels without metadata, and
rosbag2 keeps each topic's QoS in the channel metadata `offered_qos_profiles`. The metadata is rosbag2's format
version 8 (QoS as a YAML string with numeric policies): the newest one that Humble, Iron, Jazzy and later all read
(version 9's nested QoS is not readable by Humble). The directory is built next to DIR under a temporary name and
renamed into place when complete, so a failed export leaves nothing behind; an existing DIR is refused, as
`ros2 bag record` does.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import yaml
from mcap.writer import CompressionType, Writer
from mcap_ros2 import __version__ as MCAP_ROS2_VERSION
from mcap_ros2._dynamic import serialize_dynamic

from sea_hil.errors import RecordingError
from sea_hil.ros2.convert import BagMessage
from sea_hil.ros2.msgdefs import full_name, full_text

METADATA_VERSION = 8
METADATA_FILE = "metadata.yaml"
_NO_WRAP = 1 << 20   # YAML line width: long strings on one line, as yaml-cpp (rosbag2) writes them
# RMW_DURATION_INFINITE, as rosbag2 writes an unset deadline / lifespan / lease duration
INFINITE = {"sec": 9223372036, "nsec": 854775807}
# rmw enums (rmw/types.h), the numeric form of metadata version <= 8
HISTORY_KEEP_LAST, RELIABILITY_RELIABLE, DURABILITY_TRANSIENT_LOCAL, DURABILITY_VOLATILE = 1, 1, 1, 2
LIVELINESS_AUTOMATIC = 1


def qos_profile(depth: int, durability: int = DURABILITY_VOLATILE,
                lifespan: dict[str, int] | None = None) -> dict[str, Any]:
    """One offered QoS profile (reliable, keep-last `depth`) in rosbag2's YAML layout."""
    return {"history": HISTORY_KEEP_LAST, "depth": depth, "reliability": RELIABILITY_RELIABLE,
            "durability": durability, "deadline": dict(INFINITE), "lifespan": dict(lifespan or INFINITE),
            "liveliness": LIVELINESS_AUTOMATIC, "liveliness_lease_duration": dict(INFINITE),
            "avoid_ros_namespace_conventions": False}


def topic_qos(topic: str) -> dict[str, Any]:
    """What the publisher of `topic` would offer: `/rosout` as rcl's rosout publisher (keep last 1000, transient
    local, lifespan 10 s), CAN frames as ros2_socketcan's receiver (keep last 500), else rclcpp's default (10)."""
    if topic == "/rosout":
        return qos_profile(1000, DURABILITY_TRANSIENT_LOCAL, {"sec": 10, "nsec": 0})
    if topic.endswith(("/from_can_bus", "/from_can_bus_fd")):
        return qos_profile(500)
    return qos_profile(10)


def qos_yaml(topic: str) -> str:
    """The `offered_qos_profiles` string (a YAML list of one profile), as rosbag2 stores it."""
    return yaml.safe_dump([topic_qos(topic)], sort_keys=False, default_flow_style=False).rstrip("\n")


def _version(dist: str) -> str:
    try:
        return importlib_metadata.version(dist)
    except importlib_metadata.PackageNotFoundError:
        return "unknown"


@dataclass
class _Topic:
    name: str
    type_name: str
    channel_id: int
    encode: Callable[[Any], bytes]
    count: int = 0


@dataclass
class BagSummary:
    """What was written: the directory, the MCAP file, messages per topic (in the order topics first appeared)."""
    directory: Path
    mcap_path: Path
    counts: dict[str, int] = field(default_factory=dict)
    types: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())


class BagWriter:
    """The MCAP file of a bag: one schema per type (full concatenated text), one channel per topic (with its QoS),
    CDR messages; counts and time range for metadata.yaml."""

    def __init__(self, path: Path, *, chunk_size_bytes: int = 1 << 20) -> None:
        self.path = path
        self._fh = open(path, "wb")
        self._writer = Writer(self._fh, chunk_size=chunk_size_bytes, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2",
                           library=f"sea-hil {_version('sea-hil')}; mcap-ros2-support {MCAP_ROS2_VERSION}")
        self._schemas: dict[str, tuple[int, Callable[[Any], bytes]]] = {}
        self.topics: dict[str, _Topic] = {}
        self.start_ns: int | None = None
        self.end_ns = 0

    def _topic(self, topic: str, type_name: str) -> _Topic:
        t = self.topics.get(topic)
        if t is not None:
            if t.type_name != type_name:
                raise RecordingError(f"topic {topic} carries {t.type_name}, not {type_name}")
            return t
        name = full_name(type_name)
        if name not in self._schemas:
            text = full_text(name)
            schema_id = self._writer.register_schema(name, "ros2msg", text.encode())
            self._schemas[name] = (schema_id, serialize_dynamic(name, text)[name])
        schema_id, encode = self._schemas[name]
        channel_id = self._writer.register_channel(topic, "cdr", schema_id,
                                                   metadata={"offered_qos_profiles": qos_yaml(topic)})
        t = self.topics[topic] = _Topic(topic, name, channel_id, encode)
        return t

    def write(self, m: BagMessage) -> None:
        t = self._topic(m.topic, m.type_name)
        try:
            data = t.encode(m.message)
        except (TypeError, ValueError, KeyError, OverflowError) as err:   # a field the type cannot hold: a bug
            raise RecordingError(f"{m.topic}: cannot encode a {t.type_name} message: {err}") from err
        self._writer.add_message(t.channel_id, log_time=m.log_time_ns, data=data, publish_time=m.log_time_ns,
                                 sequence=m.sequence)
        t.count += 1
        if self.start_ns is None or m.log_time_ns < self.start_ns:
            self.start_ns = m.log_time_ns
        self.end_ns = max(self.end_ns, m.log_time_ns)

    def close(self, bag_metadata: dict[str, Any] | None = None) -> None:
        """Finish the file; `bag_metadata` also goes into the MCAP as metadata `rosbag2` (`serialized_metadata`), as
        rosbag2 writes it (Jazzy and later read it back from there)."""
        try:
            if bag_metadata is not None:
                self._writer.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(
                    bag_metadata, sort_keys=False, default_flow_style=False, width=_NO_WRAP)})
            self._writer.finish()
        finally:
            self._fh.close()


def bag_metadata(summary: BagSummary, custom_data: dict[str, str]) -> dict[str, Any]:
    """The `rosbag2_bagfile_information` mapping of metadata.yaml (format version 8)."""
    duration = {"nanoseconds": summary.end_ns - summary.start_ns}
    start = {"nanoseconds_since_epoch": summary.start_ns}
    rel = summary.mcap_path.name
    return {
        "version": METADATA_VERSION, "storage_identifier": "mcap", "duration": duration, "starting_time": start,
        "message_count": summary.message_count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": topic, "type": summary.types[topic], "serialization_format": "cdr",
                                "offered_qos_profiles": qos_yaml(topic), "type_description_hash": ""},
             "message_count": n}
            for topic, n in summary.counts.items()],
        "compression_format": "", "compression_mode": "", "relative_file_paths": [rel],
        "files": [{"path": rel, "starting_time": dict(start), "duration": dict(duration),
                   "message_count": summary.message_count}],
        "custom_data": dict(custom_data), "ros_distro": "",
    }


def write_bag(messages: Iterable[BagMessage], directory: str | os.PathLike[str],
              custom_data: dict[str, str] | None = None) -> BagSummary:
    """Write `messages` (log-time order) as the rosbag2 directory `directory` (must not exist), atomically."""
    out = Path(directory)
    if out.exists():
        raise RecordingError(f"{out} already exists: a rosbag2 export writes a new directory")
    parent = out.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=parent))
        os.chmod(tmp, 0o755)   # mkdtemp makes it private; the bag is an ordinary directory
    except OSError as err:
        raise RecordingError(f"cannot create {out}: {err}") from err
    try:
        writer = BagWriter(tmp / f"{out.name}_0.mcap")
        try:
            for m in messages:
                writer.write(m)
        except BaseException:
            writer.close()
            raise
        summary = BagSummary(out, out / writer.path.name,
                             {t: v.count for t, v in writer.topics.items()},
                             {t: v.type_name for t, v in writer.topics.items()},
                             writer.start_ns or 0, writer.end_ns)
        meta = bag_metadata(summary, custom_data or {})
        writer.close(meta)
        with open(tmp / METADATA_FILE, "w", encoding="utf-8") as fh:
            yaml.safe_dump({"rosbag2_bagfile_information": meta}, fh, sort_keys=False, default_flow_style=False,
                           width=_NO_WRAP)
        os.rename(tmp, out)
    except BaseException as err:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(err, OSError):
            raise RecordingError(f"cannot write the bag {out}: {err}") from err
        raise
    return summary

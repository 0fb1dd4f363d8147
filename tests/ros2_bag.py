"""Shared by the rosbag2 export tests: decode a bag with mcap-ros2-support's decoder (not the exporter's code)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from sea_hil.cli import main


def t_ns(stamp: Any) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def decode_bag(path: Path) -> dict[str, Any]:
    """Everything in the bag's MCAP file, decoded by mcap-ros2-support (not the exporter)."""
    out: dict[str, Any] = {"messages": {}, "channels": {}, "schemas": {}}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        out["profile"] = reader.get_header().profile
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        out["statistics"] = summary.statistics
        for ch in summary.channels.values():
            sch = summary.schemas[ch.schema_id]
            out["channels"][ch.topic] = (sch.name, ch.message_encoding, dict(ch.metadata))
            out["schemas"][sch.name] = (sch.encoding, sch.data.decode())
            out["messages"][ch.topic] = []
        for _, ch, msg, decoded in reader.iter_decoded_messages():
            out["messages"][ch.topic].append((msg.log_time, msg.publish_time, msg.sequence, decoded))
        out["metadata"] = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return out


def export(mcap: Path, bag: Path) -> dict[str, Any]:
    assert main(["export", str(mcap), "--ros2", str(bag)]) == 0
    return decode_bag(bag / f"{bag.name}_0.mcap")

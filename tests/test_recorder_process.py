"""The out-of-process MCAP writer: same file content as the in-process path, child death and parent death."""
from __future__ import annotations

from pathlib import Path

import can
import pytest

from protocol.can_codec import Feedback, SeaCodec, VoltageCmd
from protocol.config import load_config
from protocol.errors import RecordingError
from protocol.recorder_node import RecorderNode
from protocol.recorder_process import RecorderProcess
from protocol.recording import META_FINAL, SessionRecorder, read_session
from protocol.recording_can import RawFrame, can_records

CFG = load_config().record
CAN_TOPICS = ("/can/raw", "/can/feedback", "/can/command")


def _frames() -> list[RawFrame]:
    codec = SeaCodec()
    msgs = [codec.encode(VoltageCmd(1, (1.5, -2.0), 7)),
            *codec.encode_feedback(Feedback(1, 7, 1234, (0.1, -0.2), (0.3, 0.4), (1e-3, -2e-3), (0.01, 0.02))),
            can.Message(arbitration_id=0x21, data=b"\x00\x01", is_extended_id=False),        # VOLTAGE_CMD, bad DLC
            can.Message(arbitration_id=0x3F, data=b"", is_extended_id=False),                # unknown command id
            can.Message(arbitration_id=0x21, data=bytes(5), is_extended_id=True)]            # extended id
    return [RawFrame.of(1_000 + i, m) for i, m in enumerate(msgs)]


def _in_process(path: Path, frames: list[RawFrame]) -> None:
    codec = SeaCodec()
    with SessionRecorder.from_config(path, CFG) as rec:
        for f in frames:
            for topic, payload in can_records(codec, f)[0]:
                rec.record(topic, f.t_ns, f.t_ns, payload)


def test_child_writes_exactly_what_the_in_process_recorder_writes(tmp_path: Path) -> None:
    frames = _frames()
    _in_process(tmp_path / "a.mcap", frames)
    proc = RecorderProcess(tmp_path / "b.mcap", CFG, batch_ops=2)   # several batches
    for f in frames:
        proc.submit_can(f)
    proc.record("/tracking", 5, 4, {"t_s": 0.5, "theta1_rad": 0.1})
    proc.add_metadata("sea-hil.edge", {"x": 1})
    proc.close(final_stats={"plant_ticks": 3})
    proc.close()   # idempotent
    a, b = read_session(tmp_path / "a.mcap"), read_session(tmp_path / "b.mcap")
    assert b.complete
    for topic in CAN_TOPICS:
        assert b.messages[topic] == a.messages[topic] and a.messages[topic]
    assert len(b.messages["/can/raw"]) == len(frames)
    assert [m.payload for m in b.messages["/tracking"]] == [{"t_s": 0.5, "theta1_rad": 0.1}]
    assert b.metadata["sea-hil.edge"] == {"x": "1"}
    final = b.metadata[META_FINAL]
    assert (final["can_frames"], final["can_rejected"], final["plant_ticks"]) == ("7", "3", "3")
    assert final["closed_by"] == "close" and final["write_errors"] == "0"


def test_recorder_node_forwards_raw_frames_to_the_child(tmp_path: Path) -> None:
    proc = RecorderProcess(tmp_path / "n.mcap", CFG)
    node = RecorderNode(proc, None, "sea")
    codec = SeaCodec()
    node.on_can(codec.encode(VoltageCmd(2, (0.5, 0.25), 1)))
    proc.close(final_stats=node.counters())
    data = read_session(tmp_path / "n.mcap")
    assert [m.payload["u2_v"] for m in data.messages["/can/command"]] == [0.25]
    assert data.metadata[META_FINAL]["can_frames"] == "1"


def test_bad_payload_fails_at_the_source(tmp_path: Path) -> None:
    proc = RecorderProcess(tmp_path / "bad.mcap", CFG)
    try:
        with pytest.raises(RecordingError):
            proc.submit("/no/such/topic", 1, 1, {"a": 1})
        with pytest.raises(RecordingError):
            proc.submit("/tracking", 1, 1, {"nested": {"a": 1}})
    finally:
        proc.close()
    assert read_session(tmp_path / "bad.mcap").complete


def test_dead_child_is_counted_not_raised_and_reported_by_close(tmp_path: Path) -> None:
    proc = RecorderProcess(tmp_path / "dead.mcap", CFG, batch_ops=4)
    proc._proc.kill()
    proc._proc.wait(timeout=30)
    for i in range(20):   # several batches hit the closed pipe
        proc.submit_can(RawFrame(i, 0x21, 2, b"\x00\x00"))
    assert proc.dropped >= 16
    with pytest.raises(RecordingError, match="exited with status"):
        proc.close()


def test_parent_going_away_still_finalises_the_file(tmp_path: Path) -> None:
    proc = RecorderProcess(tmp_path / "eof.mcap", CFG)
    proc.submit_can(_frames()[0])
    proc.flush()
    proc._stdin.close()   # what the child sees when the parent dies: end of stream without CLOSE
    assert proc._proc.wait(timeout=30) == 0
    data = read_session(tmp_path / "eof.mcap")
    assert data.complete and data.metadata[META_FINAL]["closed_by"] == "eof"
    assert len(data.messages["/can/command"]) == 1

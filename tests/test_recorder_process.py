"""The out-of-process MCAP writer: same file content as the in-process path, child death and parent death; the CAN
counters (rejects, frames missed by seq gaps) both paths put into the final stats."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import can
import pytest

from sea_hil.config.loader import load_config
from sea_hil.errors import RecordingError
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import Feedback, FeedbackAngle, VoltageCmd
from sea_hil.protocol.canbus import open_bus
from sea_hil.protocol.payloads import SetpointPayload, StatePayload, TriggerReason, encode
from sea_hil.recorder.can_tap import CanTap, RawFrame, SeqGapCounter
from sea_hil.recorder.meta import META_FINAL
from sea_hil.recorder.node import RecorderNode
from sea_hil.recorder.process import RecorderProcess
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.recorder.zenoh_tap import ZenohTap
from sea_hil.stats.schema import stats_record

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
    with SessionRecorder.from_config(path, CFG) as rec:
        tap = CanTap()
        for f in frames:
            for r in tap.records(f):   # the decoded payloads, validated and encoded again by `record`
                rec.record(*r)


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
    proc.flush()          # once flushed, every batch is written or counted
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


def test_seq_gap_counter_counts_forward_gaps_per_id_only() -> None:
    gaps = SeqGapCounter()
    assert [gaps.feed(0x21, q) for q in (7, 8, 8, 11, 12)] == [0, 0, 0, 2, 0]     # a repeat is no gap
    assert [gaps.feed(0x41, q) for q in (100, 101)] == [0, 0]                     # another id: its own count
    assert [gaps.feed(0x21, q) for q in (254, 255, 1)] == [241, 0, 1]             # 12 -> 254; wraps 255 -> 0 -> 1
    assert gaps.missed == 2 + 241 + 1


def _voltage_frames(seqs: list[int], node_id: int = 1) -> list[RawFrame]:
    codec = SeaCodec()
    return [RawFrame.of(1_000 + i, codec.encode(VoltageCmd(node_id, (0.5, 0.0), q))) for i, q in enumerate(seqs)]


def _feedback_angle_frames(seqs: list[int], node_id: int = 1) -> list[RawFrame]:
    codec = SeaCodec()
    return [RawFrame.of(1_000 + i, codec.encode(FeedbackAngle(node_id, q, q, (0.0, 0.0)))) for i, q in enumerate(seqs)]


def test_can_tap_counts_frames_rejects_and_missed_feedback_and_commands() -> None:
    codec, tap = SeaCodec(), CanTap()
    fb = [RawFrame.of(i, m) for i, q in enumerate((3, 4, 6))
          for m in codec.encode_feedback(Feedback(1, q, q, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)))]
    for f in [*fb, *_voltage_frames([3, 4, 4, 9]), RawFrame(9, 0x3F, 0, b"")]:   # + one unknown id
        tap.records(f)
    feedback_missed = 3 * 1   # seq 5 of each of the 3 feedback frame ids: lost
    voltage_gaps = 4          # seq 5..8: lost, or samples the edge did not answer (counted apart)
    assert tap.counters() == {"can_frames": len(fb) + 5, "can_rejected": 1, "can_frames_missed": feedback_missed,
                              "can_command_gaps": voltage_gaps}


def test_missed_frames_reach_the_final_stats_in_both_recorder_paths(tmp_path: Path) -> None:
    frames = _feedback_angle_frames([0, 1, 2, 5, 6, 10])   # 2 + 3 missed
    proc = RecorderProcess(tmp_path / "p.mcap", CFG)
    node = RecorderNode(proc, None, "sea")
    for f in frames:
        proc.submit_can(f)
    proc.close(final_stats=node.counters())
    assert read_session(tmp_path / "p.mcap").metadata[META_FINAL]["can_frames_missed"] == "5"
    with SessionRecorder.from_config(tmp_path / "i.mcap", CFG) as rec:
        node = RecorderNode(rec, None, "sea")
        for f in frames:
            node.on_can(can.Message(timestamp=f.t_ns * 1e-9, arbitration_id=f.can_id, data=f.data,
                                    is_extended_id=False))
        counters = node.counters()
    assert (counters["can_frames"], counters["can_rejected"], counters["can_frames_missed"]) == (6, 0, 5)


def test_stopping_tap_records_what_is_still_queued(tmp_path: Path) -> None:
    """The tap pauses between batches (`tap_batch_s`); frames queued during the pause are recorded on stop."""
    channel = f"virtual:rec-stop-{uuid.uuid4().hex[:8]}"
    tap_bus, sender = open_bus(channel), open_bus(channel)
    frames = _voltage_frames(list(range(11)))
    try:
        with SessionRecorder.from_config(tmp_path / "s.mcap", CFG) as rec:
            node = RecorderNode(rec, None, "sea", tap_bus, tap_batch_s=60.0)
            node.start()
            try:
                sender.send(can.Message(arbitration_id=frames[0].can_id, data=frames[0].data, is_extended_id=False))
                assert _wait(lambda: node.tap.frames == 1, timeout_s=10.0)   # now pausing for 60 s
                for f in frames[1:]:
                    sender.send(can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False))
            finally:
                node.close()
            counters = node.counters()
    finally:
        tap_bus.shutdown()
        sender.shutdown()
    assert (counters["can_frames"], counters["can_frames_missed"], counters["can_tap_unfinished"]) == (11, 0, 0)


def _wait(cond: Callable[[], bool], timeout_s: float) -> bool:
    deadline, tick = time.monotonic() + timeout_s, threading.Event()
    while not cond():
        if time.monotonic() > deadline:
            return False
        tick.wait(0.002)
    return True


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux scheduling policies")
def test_idle_child_runs_on_idle_cpu_time_only(tmp_path: Path) -> None:
    """Real-time sessions ask for SCHED_IDLE (the child's decoding must not take a core from the 1 kHz nodes)."""
    code = ("import os; from sea_hil.recorder.process import _idle_policy; _idle_policy(); "
            "print(os.sched_getscheduler(0) == os.SCHED_IDLE)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "True"
    rec = RecorderProcess(tmp_path / "idle.mcap", load_config().record, idle=True)
    try:
        assert rec._proc.args[-2:] == ["1", "wall"]          # the flags reach the child
        rec.record("/stats", 1, 1, {"node": "edge", "final": True, "t_ns": 1})
    finally:
        rec.close()
    assert read_session(tmp_path / "idle.mcap").complete


def test_zenoh_messages_are_decoded_and_counted_by_the_child(tmp_path: Path) -> None:
    """Zenoh messages go to the child as they came (`submit_zenoh`): the file holds what the in-process Zenoh tap
    makes of them, in submission order among the frames, and the child's Zenoh counts are the final stats'."""
    state = encode(StatePayload(5, 10**12, 5_000_000, (0.1, 0.2), (0.3, 0.4), (1e-3, 2e-3), (0.01, 0.02)))
    setpoint = encode(SetpointPayload(3, 10**12, 5, (1e-4, 2e-4), (0.1, 0.2), next(iter(TriggerReason))))
    event = b'{"t_s": 0.5, "state_seq": 5, "theta1_rad": 0.1, "event": true, "reason": "TIME"}'
    good_stats = json.dumps(stats_record("edge", {"ticks": 3}, final=True, t_ns=7)).encode()
    msgs = [("sea/limb1/state", state, 100), ("sea/limb1/setpoint", setpoint, 101), ("sea/limb1/event", event, 102),
            ("sea/limb1/stats", good_stats, 103), ("sea/limb1/stats", b'{"node": 1}', 104),   # breaks the schema
            ("sea/limb1/state", b"\x00garbage", 105)]                                          # undecodable
    proc = RecorderProcess(tmp_path / "z.mcap", CFG, batch_ops=3)
    node = RecorderNode(proc, None, "sea")
    proc.submit_can(_frames()[0])
    for key, data, t in msgs:
        proc.submit_zenoh(key, data, t)
    proc.close(final_stats=node.counters())
    got = read_session(tmp_path / "z.mcap")
    tap = ZenohTap()
    want = [r for key, data, t in msgs for r in tap.take(key, data, t)]
    assert tap.stats_rejected == 1 and tap.msgs == 4
    for topic in {r.topic for r in want}:
        assert [(m.log_time_ns, m.payload) for m in got.messages[topic]] == \
            [(r.log_time_ns, r.payload) for r in want if r.topic == topic], topic
    final = got.metadata[META_FINAL]
    assert {k: final[k] for k in ("zenoh_msgs", "stats_rejected", "can_frames")} == \
        {"zenoh_msgs": "4", "stats_rejected": "1", "can_frames": "1"}
    assert final["payload_accepted"] == str(tap.payloads.as_dict()["accepted"]) != "0"
    assert float(final["recorder_cpu_s"]) > 0

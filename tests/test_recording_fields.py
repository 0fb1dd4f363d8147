"""What the recorder puts in a file (issue 18): nut velocity, the senders' sequence numbers, the log-time clock
(wall, or the drive's sample time in lockstep), Foxglove's well-known channels, the chunk count."""
from __future__ import annotations

from pathlib import Path

import jsonschema
import pytest
from mcap.reader import make_reader

from sea_hil.config.loader import config_to_toml, load_config
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Feedback, Heartbeat, VoltageCmd
from sea_hil.protocol.payloads import EventStatePayload, SetpointPayload, StatePayload, TriggerReason, encode
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.meta import META_FINAL
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.schemas import schema_for
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.recorder.zenoh_tap import ZenohTap

CODEC = SeaCodec()


def _sample(seq: int, t_us: int, wall_ns: int) -> list[RawFrame]:
    fb = Feedback(1, seq, t_us, (0.1, -0.2), (0.3, 0.4), (1e-3, -2e-3), (0.011, -0.022))
    frames = [*CODEC.encode_feedback(fb), CODEC.encode(VoltageCmd(1, (1.0, -1.0), seq))]
    return [RawFrame.of(wall_ns + i, m) for i, m in enumerate(frames)]


def _by_topic(recs):
    out: dict[str, list] = {}
    for r in recs:
        out.setdefault(r.topic, []).append(r)
    return out


def test_can_tap_records_nut_velocity_sequence_and_wall_time():
    recs = _by_topic(r for f in _sample(7, 1234, 5_000) for r in CanTap().records(f))
    fb = {k: v for r in recs["/can/feedback"] for k, v in r.payload.items()}
    assert fb["nut_vel1_m_s"] == pytest.approx(0.011, abs=1e-4) and fb["nut_vel2_m_s"] == pytest.approx(-0.022,
                                                                                                          abs=1e-4)
    assert [r.sequence for r in recs["/can/raw"]] == [7, 7, 7, 7]
    assert [r.log_time_ns for r in recs["/can/raw"]] == [5_000, 5_001, 5_002, 5_003]   # bus timestamps
    for r in recs["/can/feedback"]:
        jsonschema.validate(r.payload, schema_for("/can/feedback"))


def test_sample_time_base_logs_frames_at_the_drives_clock_across_t_us_wraps():
    tap = CanTap(time_base="sample")
    got = []
    for k in range(60, 70):   # 65.536 ms wrap of t_us between samples 65 and 66 (1 ms period)
        for f in _sample(k, (k * 1000) & 0xFFFF, 10**18 + k):
            got.extend((r.topic, r.log_time_ns) for r in tap.records(f))
    cmd_times = [t for topic, t in got if topic == "/can/command"]
    assert cmd_times == [k * 1_000_000 for k in range(60, 70)]       # VOLTAGE_CMD at the sample it answers
    assert all(t < 10**12 for _, t in got)


def test_heartbeat_changes_go_to_the_faults_log():
    tap = CanTap()
    hb = [Heartbeat(1, DriverState.RUNNING, ErrorFlags(0), 0, 0, 1), Heartbeat(1, DriverState.RUNNING,
          ErrorFlags(0), 0, 0, 2), Heartbeat(1, DriverState.FAULT, ErrorFlags.WATCHDOG, 0, 0, 3)]
    logs = [r.payload for i, h in enumerate(hb) for r in tap.records(RawFrame.of(i, CODEC.encode(h)))
            if r.topic == "/log/faults"]
    assert [(p["level"], p["name"]) for p in logs] == [(2, "driver1"), (4, "driver1")]   # INFO, then ERROR
    assert "FAULT" in logs[1]["message"] and "WATCHDOG" in logs[1]["message"]
    bad = tap.records(RawFrame(9, 0x21, 2, b"\x00\x01"))   # VOLTAGE_CMD with a bad DLC
    assert [r.payload["level"] for r in bad if r.topic == "/log/faults"] == [3]
    for p in logs:
        jsonschema.validate(p, schema_for("/log/faults"))


def test_zenoh_tap_records_nut_velocity_joint_states_and_answers_at_the_state_sample_time():
    tap = ZenohTap(time_base="sample")
    state = encode(StatePayload(41, 123, 7_000_000, (0.1, 0.2), (0.3, 0.4), (1e-3, 2e-3), (0.05, -0.06)))
    recs = _by_topic(tap.records("sea/limb1/state", state, 10**18))
    st = recs["/zenoh/state"][0]
    assert (st.log_time_ns, st.publish_time_ns, st.sequence) == (7_000_000, 7_000_000, 41)
    assert (st.payload["nut_vel1_m_s"], st.payload["nut_vel2_m_s"]) == (0.05, -0.06)
    js = recs["/joint_states"][0]
    jsonschema.validate(js.payload, schema_for("/joint_states"))
    assert [j["name"] for j in js.payload["joints"]][:2] == ["hip", "knee"]
    assert js.payload["timestamp"] == {"sec": 0, "nsec": 7_000_000}
    sp = encode(SetpointPayload(5, 999, 41, (1e-3, 2e-3), (0.1, 0.2), TriggerReason.ERROR_BOUND))
    (rec,) = tap.records("sea/limb1/setpoint", sp, 10**18 + 5)
    assert (rec.topic, rec.log_time_ns, rec.sequence) == ("/zenoh/setpoint", 7_000_000, 5)
    wall = ZenohTap().records("sea/limb1/state", state, 10**18)[0]
    assert wall.log_time_ns == wall.publish_time_ns == 10**18 and wall.payload["sent_t_ns"] == 123


def test_an_edge_trigger_state_records_its_event_number_reason_and_trajectory():
    data = encode(EventStatePayload(41, 123, 7_000_000, (0.1, 0.2), (0.3, 0.4), (1e-3, 2e-3), (0.05, -0.06), 9,
                                    TriggerReason.ERROR_BOUND, 77))
    st = _by_topic(ZenohTap().records("sea/limb1/state", data, 10**18))["/zenoh/state"][0]
    assert (st.sequence, st.payload["seq"], st.payload["event_seq"]) == (41, 41, 9)   # MCAP sequence: the sample's
    assert (st.payload["reason"], st.payload["trajectory_id"]) == ("ERROR_BOUND", 77)
    jsonschema.validate(st.payload, schema_for("/zenoh/state"))
    plain = encode(StatePayload(41, 123, 7_000_000, (0.1, 0.2), (0.3, 0.4), (1e-3, 2e-3), (0.05, -0.06)))
    assert "event_seq" not in ZenohTap().records("sea/limb1/state", plain, 10**18)[0].payload


def test_sequence_reaches_the_file_and_final_metadata_counts_every_chunk(tmp_path: Path):
    path = tmp_path / "s.mcap"
    with SessionRecorder(path, chunk_size_bytes=4096, flush_period_s=None) as rec:
        for i in range(1, 400):
            rec.record("/can/command", i, i, {"node_id": 1, "seq": i % 256, "u1_v": 0.5}, sequence=i % 256)
        with pytest.raises(Exception, match="u32"):
            rec.record("/can/command", 1, 1, {"node_id": 1}, sequence=-1)
    with path.open("rb") as fh:
        reader = make_reader(fh)
        seqs = [m.sequence for _, _, m in reader.iter_messages()]
        chunks = len(reader.get_summary().chunk_indexes)
    assert seqs == [i % 256 for i in range(1, 400)]
    data = read_session(path)
    assert chunks > 1 and int(data.metadata[META_FINAL]["chunks_written"]) == chunks == data.chunks


def test_a_latch_line_reports_the_newest_feedback_of_each_joint():
    """With the session's config, a heartbeat that latches a limit fault gets one /log/faults line naming the
    limit and the drive's newest measured values: the angles of its last FEEDBACK_ANGLE, each joint's velocity from
    its own last FEEDBACK_JOINTn."""
    tap = CanTap()
    tap.configure(config_to_toml(load_config()))
    fb = Feedback(1, 5, 5000, (0.9, 0.2), (0.5, 3.5), (1e-3, 2e-3), (0.0, 0.0))
    angle, _, joint2 = (CODEC.encode(p) for p in fb.parts())
    older = CODEC.encode(Feedback(1, 4, 4000, (0.1, 0.1), (2.5, 0.1), (0.0, 0.0), (0.0, 0.0)).parts()[1])
    hb = Heartbeat(1, DriverState.FAULT, ErrorFlags.POSITION_LIMIT | ErrorFlags.VELOCITY_LIMIT, 0, 0, 6)
    frames = [older, angle, joint2, CODEC.encode(hb)]   # joint1's newest velocity is the older 2.5 rad/s
    lines = [r.payload["message"] for i, m in enumerate(frames) for r in tap.records(RawFrame.of(i, m))
             if r.topic == "/log/faults" and "latched" in r.payload["message"]]
    assert len(lines) == 1
    assert "hip angle 0.9" in lines[0] and "position_max_rad[0]" in lines[0]
    assert "hip velocity 2.5" in lines[0] and "knee velocity 3.5" in lines[0]

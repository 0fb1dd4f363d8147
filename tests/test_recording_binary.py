"""The binary (protobuf) CAN channels and the bulk MCAP path: the bulk writer writes the library's bytes, every binary
message decodes with an independent protobuf decoder (the `protobuf` package's own parser driven only by the
FileDescriptorSet read from the file) to the source values, and a recorder-process session file holds exactly what
the frames said."""
from __future__ import annotations

import io
import math
import random
from pathlib import Path

import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from sea_hil.config.loader import load_config
from sea_hil.errors import RecordingError
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import Feedback, FeedbackAngle, FeedbackJoint1, FeedbackJoint2, VoltageCmd
from sea_hil.recorder import binary
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.mcap_bulk import BulkWriter
from sea_hil.recorder.process import RecorderProcess
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.writer import SessionRecorder


def _messages(n: int, seed: int = 3) -> list[tuple[int, int, bytes, int, int]]:
    rng = random.Random(seed)
    return [(rng.choice((1, 2, 3)), rng.randrange(0, 10**12), rng.randbytes(rng.randrange(0, 90)),
             rng.randrange(0, 10**12), rng.randrange(0, 1 << 32)) for _ in range(n)]


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.NONE])
def test_bulk_writer_writes_the_librarys_bytes(compression: CompressionType) -> None:
    msgs = _messages(3000)
    files = []
    for bulk in (False, True):
        out = io.BytesIO()
        w = (BulkWriter if bulk else Writer)(out, chunk_size=4096, compression=compression)
        w.start(profile="", library="t")
        sid = w.register_schema("s", "protobuf", b"x")
        for topic in ("/a", "/b", "/c"):
            w.register_channel(topic, "protobuf", sid)
        if bulk:
            assert isinstance(w, BulkWriter) and w.bulk_supported
            for i in range(0, len(msgs), 97):   # batches that straddle chunk ends
                w.add_messages(msgs[i:i + 97])
        else:
            for m in msgs:
                w.add_message(*m)
        w.finish()
        files.append(out.getvalue())
    assert files[0] == files[1]
    assert sum(1 for _ in make_reader(io.BytesIO(files[1])).iter_messages()) == len(msgs)


def _frames() -> list[RawFrame]:
    """Frames of every recorded kind, as the driver and the edge send them (plus one the DBC refuses)."""
    return [f for f, _ in _frames_and_expected()]


def _frames_and_expected() -> list[tuple[RawFrame, dict[str, dict]]]:
    """Each frame with the messages its binary channels must hold (topic -> payload), written out here from the
    frame's decoded values (the schema's fields, docs/recording.md), not through the recorder's own mapping."""
    codec = SeaCodec(fd=None)
    out: list[tuple[RawFrame, dict[str, dict]]] = []
    for k in range(40):
        q = k % 256
        for obj in (FeedbackAngle(1, q, 1000 * k, (0.01 * k, -0.02 * k)),
                    FeedbackJoint1(1, q, 0.1 * k, 1e-4 * k, -1e-3 * k),
                    FeedbackJoint2(1, q, -0.1 * k, -1e-4 * k, 1e-3 * k),
                    VoltageCmd(1, (0.5 * k - 10, 12.0 - 0.25 * k), q)):
            msg = codec.encode(obj)
            d = codec.decode(msg)   # the values the frame carries (the DBC's resolution)
            if isinstance(d, FeedbackAngle):
                decoded = ("/can/feedback", {"t_us": d.t_us, "theta1_rad": d.theta_rad[0],
                                             "theta2_rad": d.theta_rad[1]})
            elif isinstance(d, FeedbackJoint1 | FeedbackJoint2):
                j = 1 if isinstance(d, FeedbackJoint1) else 2
                decoded = ("/can/feedback", {f"omega{j}_rad_s": d.omega_rad_s, f"delta{j}_m": d.delta_m,
                                             f"nut_vel{j}_m_s": d.nut_vel_m_s})
            else:
                assert isinstance(d, VoltageCmd)
                decoded = ("/can/command", {"kind": "voltage", "u1_v": d.voltage_v[0], "u2_v": d.voltage_v[1]})
            out.append((RawFrame.of(10**9 + 250_000 * len(out), msg),
                        {"/can/raw": {"can_id": msg.arbitration_id, "dlc": msg.dlc, "data_hex": bytes(msg.data).hex(),
                                      "direction": "rx", "is_extended": False, "node_id": 1},
                         decoded[0]: {"node_id": 1, "seq": q, **decoded[1]}}))
    bad = RawFrame(10**9 + 250_000 * len(out), 0x7FF, 2, b"\x01\x02")   # unknown id: /can/raw only
    out.append((bad, {"/can/raw": {"can_id": 0x7FF, "dlc": 2, "data_hex": "0102", "direction": "rx",
                                   "is_extended": False, "node_id": 0x7FF >> 5}}))
    return out


def _independent_classes(schema_data: bytes, names: list[str]) -> dict[str, type]:
    """Message classes built from the file's FileDescriptorSet alone (not from sea_hil.recorder.binary)."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return {n: message_factory.GetMessageClass(pool.FindMessageTypeByName(n)) for n in names}


def test_binary_channels_decode_independently_to_the_source_values(tmp_path: Path) -> None:
    pairs = _frames_and_expected()
    frames = [f for f, _ in pairs]
    expected: dict[str, list[dict]] = {t: [] for t in binary.BINARY_TOPICS}
    for _, messages in pairs:
        for topic, payload in messages.items():
            expected[topic].append(payload)
    path = tmp_path / "p.mcap"
    rp = RecorderProcess(path, load_config().record)
    for i in range(0, len(frames), 7):
        rp.submit_can_batch([tuple(f) for f in frames[i:i + 7]])
    rp.close()

    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        got: dict[str, list[dict]] = {t: [] for t in binary.BINARY_TOPICS}
        for schema, channel, message in reader.iter_messages(topics=sorted(binary.BINARY_TOPICS)):
            assert (schema.encoding, channel.message_encoding) == ("protobuf", "protobuf")
            cls = _independent_classes(schema.data, [schema.name])[schema.name]
            m = cls.FromString(message.data)
            got[channel.topic].append({f.name: v for f, v in m.ListFields()})
    for topic in binary.BINARY_TOPICS:
        assert len(got[topic]) == len(expected[topic]) > 0, topic
        for g, e in zip(got[topic], expected[topic], strict=True):
            assert g.keys() == e.keys()
            for k, v in e.items():
                assert g[k] == v and type(g[k]) is type(v), (topic, k)   # doubles round-trip bit for bit
    # and the project's reader gives the same dicts, and the in-process writer the same file content
    data = read_session(path)
    assert data.undecodable == 0
    for topic in binary.BINARY_TOPICS:
        assert [m.payload for m in data.messages[topic]] == expected[topic]
        assert data.encodings[topic] == ("protobuf", "protobuf")
    assert data.metadata["sea-hil.final"]["can_frames"] == str(len(frames))


def test_binary_encoding_checks_fields_and_keeps_json_nulls() -> None:
    with pytest.raises(RecordingError, match="cannot encode"):
        binary.encode("/can/command", {"node_id": 1, "not_a_field": 2.0})
    with pytest.raises(RecordingError, match="cannot encode"):
        binary.encode("/can/feedback", {"node_id": 1, "theta1_rad": "x"})
    p = {"node_id": 1, "seq": 2, "theta1_rad": math.nan, "theta2_rad": None, "t_us": None}
    assert binary.decode("/can/feedback", binary.encode("/can/feedback", p)) == \
        {"node_id": 1, "seq": 2, "theta1_rad": None, "theta2_rad": None}   # as JSON's null read back
    with pytest.raises(RecordingError, match="undecodable"):
        binary.decode("/can/raw", b"\xff\xff\xff")


def test_record_batch_counts_a_bad_message_and_writes_the_rest(tmp_path: Path) -> None:
    path = tmp_path / "b.mcap"
    with SessionRecorder(path) as rec:
        n = rec.record_batch([("/can/command", 5, 5, {"node_id": 1, "seq": 1, "u1_v": 1.0}, 1),
                              ("/can/command", 6, 6, {"seq": 2}, 2),               # node_id missing
                              ("/zenoh/voltage", 7, 7, {"seq": 3, "u1_v": 2.0}, 3)])
        assert n == 2 and rec.write_errors == 1
    data = read_session(path)
    assert [m.payload for m in data.messages["/can/command"]] == [{"node_id": 1, "seq": 1, "u1_v": 1.0}]
    assert [m.sequence for m in data.messages["/zenoh/voltage"]] == [3]
    assert data.metadata["sea-hil.final"]["messages./can/command"] == "1"


def test_in_process_and_bulk_paths_write_the_same_messages(tmp_path: Path) -> None:
    frames = _frames()
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    with SessionRecorder(a) as rec:
        tap = CanTap()
        for f in frames:
            for r in tap.records(f):
                rec.record(*r)
    with SessionRecorder(b) as rec:
        tap = CanTap()
        rec.record_batch([r for f in frames for r in tap.records(f)])
    ra, rb = read_session(a), read_session(b)
    assert ra.messages == rb.messages and ra.message_count == rb.message_count > len(frames)


def test_the_taps_encoding_is_the_checked_encoders_byte_for_byte() -> None:
    """`CanTap.encode` serializes its own payloads unchecked and builds `/can/raw` from cached pieces around the
    data: every message must be what `binary.encode` writes for the payload a reader decodes from it."""
    rng = random.Random(7)
    codec = SeaCodec(fd=True)
    frames = [tuple(f) for f in _frames()]
    for n in (*range(0, 9), 12, 16, 20, 24, 32, 48, 63, 64):   # every classic and FD length, odd ones too
        for ext, fd in ((False, False), (True, False), (False, True)):
            can_id = rng.randrange(1 << 29 if ext else 1 << 11)
            frames.append((rng.randrange(10**18), can_id, n, rng.randbytes(n), ext, False, False, fd))
    fb = codec.encode(Feedback(3, 200, 60_000, (0.5, -0.5), (1.0, -1.0), (1e-3, -1e-3), (0.01, -0.01)))
    frames.append((5, fb.arbitration_id, fb.dlc, bytes(fb.data), False, False, False, True))   # FEEDBACK_FD
    tap = CanTap()
    out = tap.encode(frames)
    assert {m[0] for m in out} >= {*binary.BINARY_TOPICS, "/log/faults"}
    for topic, _, _, data, _ in out:
        if topic in binary.BINARY_TOPICS:
            assert binary.encode(topic, binary.decode(topic, data)) == data, topic
    raws = [binary.decode("/can/raw", m[3]) for m in out if m[0] == "/can/raw"]
    assert len(raws) == len(frames) == tap.frames
    for raw, (_, can_id, dlc, data, ext, _, _, fd) in zip(raws, frames, strict=True):
        assert raw == {"can_id": can_id, "dlc": dlc, "data_hex": data.hex(), "direction": "rx", "is_extended": ext,
                       "node_id": can_id >> 5, **({"is_fd": True} if fd else {})}

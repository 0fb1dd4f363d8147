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
from sea_hil.protocol.can_frames import FeedbackAngle, FeedbackJoint1, FeedbackJoint2, VoltageCmd
from sea_hil.recorder import binary
from sea_hil.recorder.can_tap import CanTap, RawFrame, can_records
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
    codec = SeaCodec(fd=None)
    out: list[RawFrame] = []
    for k in range(40):
        for obj in (FeedbackAngle(1, k % 256, 1000 * k, (0.01 * k, -0.02 * k)),
                    FeedbackJoint1(1, k % 256, 0.1 * k, 1e-4 * k, -1e-3 * k),
                    FeedbackJoint2(1, k % 256, -0.1 * k, -1e-4 * k, 1e-3 * k),
                    VoltageCmd(1, (0.5 * k - 10, 12.0 - 0.25 * k), k % 256)):
            msg = codec.encode(obj)
            out.append(RawFrame.of(10**9 + 250_000 * len(out), msg))
    out.append(RawFrame(10**9 + 250_000 * len(out), 0x7FF, 2, b"\x01\x02"))   # unknown id: /can/raw only
    return out


def _independent_classes(schema_data: bytes, names: list[str]) -> dict[str, type]:
    """Message classes built from the file's FileDescriptorSet alone (not from sea_hil.recorder.binary)."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return {n: message_factory.GetMessageClass(pool.FindMessageTypeByName(n)) for n in names}


def test_binary_channels_decode_independently_to_the_source_values(tmp_path: Path) -> None:
    frames = _frames()
    codec = SeaCodec(fd=None)
    expected = {t: [] for t in binary.BINARY_TOPICS}
    for f in frames:
        for topic, payload in can_records(codec, f)[0]:
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

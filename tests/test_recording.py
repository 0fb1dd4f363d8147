"""MCAP session recorder/reader: round trip, schemas, metadata, drop policy, truncation recovery, signals."""
from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import jsonschema
import pytest
from mcap.reader import make_reader

from sea_hil.config.loader import load_config
from sea_hil.errors import RecordingError
from sea_hil.recorder.meta import CONFIG_ATTACHMENT, META_CONFIG, META_FINAL, META_SESSION
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.schemas import TOPICS, encodings, schema_for
from sea_hil.recorder.well_known import LogLevel, joint_states, log_message
from sea_hil.recorder.writer import SessionRecorder, install_finalizer

REPO = Path(__file__).resolve().parents[1]
TIMEOUT_S = 20.0

SAMPLES = {
    "/can/raw": {"t_ns": 1, "can_id": 0x181, "is_extended": False, "dlc": 8, "data_hex": "0011223344556677",
                 "direction": "rx", "node_id": 1},
    "/can/feedback": {"t_ns": 2, "node_id": 1, "seq": 5, "theta1_rad": 0.1, "theta2_rad": -0.2, "omega1_rad_s": 0.0,
                      "omega2_rad_s": 1.5, "delta1_m": 1e-4, "delta2_m": -2e-4, "status": 0},
    "/can/command": {"t_ns": 3, "node_id": 1, "seq": 6, "kind": "voltage", "u1_v": 3.5, "u2_v": -24.0},
    "/zenoh/state": {"t_ns": 4, "seq": 7, "theta1_rad": 0.1, "theta2_rad": 0.2, "latency_s": 0.0012},
    "/zenoh/setpoint": {"t_ns": 5, "seq": 8, "event_index": 3, "delta1_ref_m": 1e-3, "delta2_ref_m": 2e-3},
    "/zenoh/voltage": {"t_ns": 6, "seq": 9, "u1_v": 1.0, "u2_v": 2.0},
    "/controller/event": {"t_ns": 7, "event_index": 3, "reason": "threshold", "inter_event_s": 0.05,
                          "error_norm": 0.21, "threshold": 0.2},
    "/stats": {"node": "edge", "final": False, "t_ns": 8, "uplink_msgs": 100, "loop_us_p99": 13.5},
    "/tracking": {"t_ns": 9, "theta1_d_rad": 0.3, "theta1_rad": 0.29, "e1_rad": 0.01, "e2_rad": -0.02},
    "/log/events": log_message(10, LogLevel.INFO, "controller", "trigger event ERROR_BOUND"),
    "/log/faults": log_message(10, LogLevel.ERROR, "driver1", "driver 1: FAULT"),
    "/joint_states": joint_states(11, (0.1, 0.2), (0.0, 1.0), (1e-4, -1e-4)),
}


def _expected(n: int) -> dict[str, list[tuple[int, dict]]]:
    return {topic: [(1000 * i + k, {**p, "t_ns": 1000 * i + k}) for i in range(n)]
            for k, (topic, p) in enumerate(SAMPLES.items())}


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_session_round_trip(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "s.mcap"
    cfg = load_config()
    expected = _expected(40)
    with SessionRecorder(path, compression=compression, chunk_size_bytes=2048) as rec:
        rec.write_session_header(cfg, seed=42, argv=["sea-hil", "run"], extra={"role": "test"})
        for topic, msgs in expected.items():
            for i, (t, payload) in enumerate(reversed(msgs)):  # out of order: reader sorts by log_time
                (rec.submit if i % 2 else rec.record)(topic, t, t + 1, payload)
    data = read_session(path)
    assert data.complete and data.tail_error is None and data.undecodable == 0
    assert set(data.messages) == set(TOPICS) and set(data.schemas) == set(TOPICS)
    for topic, msgs in expected.items():
        assert data.encodings[topic] == encodings(topic) == (("protobuf", "protobuf") if topic.startswith("/can/")
                                                              else ("jsonschema", "json"))
        assert data.schemas[topic] == schema_for(topic)
        got = data.messages[topic]
        assert [(m.log_time_ns, m.payload) for m in got] == msgs
        assert all(m.publish_time_ns == m.log_time_ns + 1 for m in got)
        validator = jsonschema.Draft202012Validator(data.schemas[topic])
        for m in got:
            validator.validate(m.payload)
    session = data.metadata[META_SESSION]
    assert session["seed"] == "42" and session["argv"] == '["sea-hil", "run"]' and session["role"] == "test"
    assert {"version.mcap", "version.numpy", "version.python-can", "version.eclipse-zenoh", "host", "python"} <= set(
        session)
    assert data.metadata[META_CONFIG]["record.compression"] == '"zstd"'
    assert load_config(overrides=tomllib.loads(data.attachments[CONFIG_ATTACHMENT].decode())) == cfg
    final = data.metadata[META_FINAL]
    assert final["written"] == str(40 * len(TOPICS)) and final["dropped"] == "0" and final["closed_by"] == "close"
    with open(path, "rb") as f:  # the standard indexed reader agrees
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 40 * len(TOPICS)
        assert all(summary.schemas[c.schema_id].encoding == encodings(c.topic)[0] for c in summary.channels.values())
        assert sum(1 for _ in reader.iter_messages()) == 40 * len(TOPICS)
        assert [a.name for a in reader.iter_attachments()] == [CONFIG_ATTACHMENT]


def test_bad_input_is_rejected_with_recording_error(tmp_path: Path) -> None:
    rec = SessionRecorder(tmp_path / "b.mcap", compression="none")
    with pytest.raises(RecordingError, match="unknown recording topic"):
        rec.submit("/nope", 0, 0, {})
    with pytest.raises(RecordingError, match="missing required"):
        rec.record("/can/raw", 0, 0, {"can_id": 1})
    with pytest.raises(RecordingError, match="flat scalar"):
        rec.record("/tracking", 0, 0, {"e1_rad": [1.0, 2.0]})
    with pytest.raises(RecordingError, match="misses"):
        rec.record("/stats", 0, 0, {"name": "text"})
    with pytest.raises(RecordingError, match="finite number"):
        rec.record("/stats", 0, 0, {"node": "edge", "final": True, "t_ns": 0, "name": "text"})
    with pytest.raises(RecordingError, match="compression"):
        SessionRecorder(tmp_path / "c.mcap", compression="gzip")
    rec.close()
    rec.close()  # idempotent
    with pytest.raises(RecordingError, match="closed"):
        rec.record("/tracking", 0, 0, {})
    with pytest.raises(RecordingError, match="cannot read"):
        read_session(tmp_path / "missing.mcap")
    (tmp_path / "junk.mcap").write_bytes(b"hello world, not mcap")
    with pytest.raises(RecordingError, match="not an MCAP"):
        read_session(tmp_path / "junk.mcap")


def test_full_queue_drops_and_counts(tmp_path: Path) -> None:
    gate = threading.Event()
    rec = SessionRecorder(tmp_path / "d.mcap", queue_limit=3, writer_gate=gate)
    results = [rec.submit("/zenoh/voltage", i, i, {"seq": i, "u1_v": 0.5}) for i in range(10)]
    assert results == [True] * 3 + [False] * 7
    assert rec.dropped == 7 and rec.counters()["queued"] == 3
    gate.set()
    rec.close()
    data = read_session(tmp_path / "d.mcap")
    assert [m.payload["seq"] for m in data.messages["/zenoh/voltage"]] == [0, 1, 2]
    assert data.metadata[META_FINAL]["dropped"] == "7" and data.metadata[META_FINAL]["written"] == "3"


def test_truncated_file_yields_a_prefix_of_messages(tmp_path: Path) -> None:
    path = tmp_path / "t.mcap"
    with SessionRecorder(path, chunk_size_bytes=1024) as rec:
        rec.write_session_header(load_config())
        for i in range(300):
            rec.record("/zenoh/state", i, i, {"seq": i, "theta1_rad": i * 1e-3})
    blob = path.read_bytes()
    previous = -1
    for cut in range(len(blob) // 10, len(blob), len(blob) // 10):
        (tmp_path / "cut.mcap").write_bytes(blob[:cut])
        data = read_session(tmp_path / "cut.mcap")
        seqs = [m.payload["seq"] for m in data.messages.get("/zenoh/state", [])]
        assert not data.complete and data.tail_error is not None
        assert seqs == list(range(len(seqs))) and len(seqs) >= previous
        previous = len(seqs)
    assert previous > 0 and data.metadata[META_SESSION] and data.attachments[CONFIG_ATTACHMENT]


CHILD = r"""
import signal, sys, threading
from sea_hil.recorder.writer import SessionRecorder, install_finalizer
path, mode = sys.argv[1], sys.argv[2]
rec = SessionRecorder(path, compression="zstd", chunk_size_bytes=512)
rec.write_session_header(None, seed=1)
if mode == "term":
    install_finalizer(rec)
    for i in range(100):
        rec.submit("/zenoh/state", i, i, {"seq": i, "theta1_rad": 0.5})
    print("ready", flush=True)
    threading.Event().wait(60)
    sys.exit(3)
chunks = 0
for i in range(200_000):
    rec.record("/zenoh/state", i, i, {"seq": i, "theta1_rad": i * 1e-4, "theta2_rad": 0.25})
    if rec.chunks_written != chunks:
        chunks = rec.chunks_written
        print(f"chunks {chunks} messages {rec.written}", flush=True)
threading.Event().wait(60)  # never end on its own before the parent's SIGKILL
"""


def _start_child(path: Path, mode: str) -> tuple[subprocess.Popen[str], queue.Queue[str]]:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path), mode], stdout=subprocess.PIPE, text=True,
                            env=env, cwd=REPO)
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            lines.put(line)
    threading.Thread(target=pump, daemon=True).start()
    return proc, lines


def _end(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=TIMEOUT_S)


def test_sigkill_recovers_every_completed_chunk(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    proc, lines = _start_child(path, "kill")
    try:
        while True:
            words = lines.get(timeout=TIMEOUT_S).split()
            if words[0] == "chunks" and int(words[1]) >= 5:
                safe = int(words[3])
                break
        proc.send_signal(signal.SIGKILL)
        assert proc.wait(timeout=TIMEOUT_S) == -signal.SIGKILL
    finally:
        _end(proc)
    data = read_session(path)
    seqs = [m.payload["seq"] for m in data.messages["/zenoh/state"]]
    assert not data.complete and META_FINAL not in data.metadata and data.metadata[META_SESSION]["seed"] == "1"
    assert data.chunks >= 5 and len(seqs) >= safe
    assert seqs == list(range(len(seqs)))


def test_sigterm_finalises_the_file(tmp_path: Path) -> None:
    path = tmp_path / "termed.mcap"
    proc, lines = _start_child(path, "term")
    try:
        assert lines.get(timeout=TIMEOUT_S).strip() == "ready"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=TIMEOUT_S) == 128 + signal.SIGTERM
    finally:
        _end(proc)
    with open(path, "rb") as f:
        assert make_reader(f).get_summary() is not None
    data = read_session(path)
    assert data.complete and len(data.messages["/zenoh/state"]) == 100
    assert data.metadata[META_FINAL]["closed_by"] == "SIGTERM" and data.metadata[META_FINAL]["written"] == "100"


def test_signal_inside_a_write_is_deferred_until_the_write_ends(tmp_path: Path) -> None:
    rec = SessionRecorder(tmp_path / "f.mcap", compression="none")
    uninstall = install_finalizer(rec, signals=(signal.SIGUSR1,))
    try:
        handler = signal.getsignal(signal.SIGUSR1)
        with pytest.raises(SystemExit) as exc:
            handler(signal.SIGUSR1, None)  # type: ignore[operator]
        assert exc.value.code == 128 + signal.SIGUSR1
        rec._writing_thread = threading.get_ident()  # as if the signal arrived inside add_message
        handler(signal.SIGUSR1, None)  # type: ignore[operator]
        rec._writing_thread = None
        with pytest.raises(SystemExit):
            rec.record("/tracking", 1, 1, {"e1_rad": 0.0})
        assert rec.written == 1
    finally:
        uninstall()
        rec.close()
    assert read_session(tmp_path / "f.mcap").metadata[META_FINAL]["closed_by"] == "SIGUSR1"


def test_flush_period_makes_messages_readable_while_open(tmp_path: Path) -> None:
    path = tmp_path / "live.mcap"
    rec = SessionRecorder(path, chunk_size_bytes=1 << 20, flush_period_s=0.0)  # 0: close a chunk per message
    try:
        for i in range(5):
            rec.record("/zenoh/voltage", i, i, {"seq": i, "u1_v": 1.0})
            assert rec.chunks_written == i + 1
        live = read_session(path)
        assert not live.complete and [m.payload["seq"] for m in live.messages["/zenoh/voltage"]] == list(range(5))
    finally:
        rec.close()
    assert read_session(path).complete

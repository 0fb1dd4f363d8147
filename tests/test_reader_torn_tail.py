"""The MCAP reader turns only a torn or corrupt file into a "torn tail" (`tail_error`): a bug while handling a
record (here: in building a message) propagates instead of silently truncating the session."""
from __future__ import annotations

import random
from pathlib import Path

import pytest

import sea_hil.recorder.reader as reader
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.writer import SessionRecorder


@pytest.fixture(scope="module")
def blob(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("torn") / "t.mcap"
    with SessionRecorder(path, chunk_size_bytes=512) as rec:
        for i in range(100):
            rec.record("/zenoh/state", i, i, {"seq": i, "theta1_rad": i * 1e-3})
    return path.read_bytes()


def test_every_cut_and_corruption_is_a_torn_tail_not_an_exception(tmp_path: Path, blob: bytes) -> None:
    rng = random.Random(12)
    cut_path = tmp_path / "cut.mcap"
    errors = set()
    for cut in sorted(rng.sample(range(9, len(blob)), 40)):
        cut_path.write_bytes(blob[:cut])
        data = read_session(cut_path)
        assert not data.complete and data.tail_error is not None
        errors.add(data.tail_error.split(":")[0])
    for _ in range(40):                       # a flipped byte: CRC, length, opcode or string garbage
        b = bytearray(blob)
        b[rng.randrange(9, len(b))] ^= 1 << rng.randrange(8)
        cut_path.write_bytes(bytes(b))
        data = read_session(cut_path)
        assert data.complete or data.tail_error is not None
    assert "EndOfFile" in errors


def test_a_bug_in_record_handling_is_not_a_torn_tail(tmp_path: Path, blob: bytes, monkeypatch) -> None:
    path = tmp_path / "whole.mcap"
    path.write_bytes(blob)
    assert read_session(path).complete

    def broken(*args: object) -> None:
        raise TypeError("bug in the callback")
    monkeypatch.setattr(reader, "RecordedMessage", broken)
    with pytest.raises(TypeError, match="bug in the callback"):
        read_session(path)

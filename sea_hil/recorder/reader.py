"""Reading a session MCAP file back: every message per topic, schemas, metadata, attachments; truncation-tolerant.
JSON messages and the protobuf CAN channels (`sea_hil.recorder.binary`) come back as the same flat dicts."""
from __future__ import annotations

import json
import os
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, BinaryIO, NamedTuple

import zstandard
from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import MCAP0_MAGIC

from sea_hil.errors import RecordingError
from sea_hil.recorder import binary
from sea_hil.recorder.schemas import schema_for


def _codec_errors() -> tuple[type[BaseException], ...]:
    """What the chunk decompressors raise on a cut or corrupt chunk (zstd: ZstdError; lz4: RuntimeError)."""
    return (RuntimeError, zstandard.ZstdError)   # zstandard: a dependency of mcap


# what the MCAP parser raises past the last good record of a torn or truncated file: end of data, a record length or
# magic that is garbage (McapError), a CRC mismatch (CRCValidationError is a ValueError), an undecodable string or
# field (ValueError, struct.error), a cut compressed chunk, a garbage length inside a record (MemoryError: the
# parser allocates it before reading)
TORN_TAIL_ERRORS: tuple[type[BaseException], ...] = (McapError, ValueError, struct.error, EOFError, MemoryError,
                                                     *_codec_errors())


def _records(f: BinaryIO, out: SessionData) -> Iterator[Any]:
    """Every record of the file, chunks broken up (all-or-nothing per chunk, CRC checked). Stops at the first torn
    record and notes why in `out.tail_error`; exceptions of the caller's loop body are not caught here."""
    size = os.fstat(f.fileno()).st_size          # no record is longer than the file: a garbage length is an error,
    it = iter(StreamReader(f, emit_chunks=True, record_size_limit=size).records)   # not a huge allocation
    while True:
        try:
            rec = next(it)
            inner = breakup_chunk(rec, validate_crc=True) if isinstance(rec, Chunk) else [rec]
        except StopIteration:
            return
        except TORN_TAIL_ERRORS as err:
            out.tail_error = f"{type(err).__name__}: {err}"
            return
        out.chunks += isinstance(rec, Chunk)
        yield from inner


class RecordedMessage(NamedTuple):
    log_time_ns: int
    publish_time_ns: int
    payload: dict[str, Any]
    sequence: int = 0   # the sender's sequence number (MCAP `sequence`)


@dataclass
class SessionData:
    """Everything read back from a session file. `complete` (footer and closing magic read) is False for a
    truncated (recovered) file; `tail_error` then says why reading stopped, `chunks` counts complete chunks."""
    messages: dict[str, list[RecordedMessage]] = field(default_factory=dict)
    schemas: dict[str, dict[str, Any]] = field(default_factory=dict)  # JSON schema (of the decoded payloads)
    encodings: dict[str, tuple[str, str]] = field(default_factory=dict)  # topic -> (schema enc, message enc)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    complete: bool = False
    chunks: int = 0
    undecodable: int = 0
    tail_error: str | None = None

    @property
    def message_count(self) -> int:
        return sum(len(v) for v in self.messages.values())


def read_session(path: str | os.PathLike[str],
                 on_message: Callable[[str, RecordedMessage], None] | None = None) -> SessionData:
    """Read all messages (per topic, log_time order), schemas, metadata and attachments. Works on truncated files
    (no summary/footer after SIGKILL): every complete chunk is read, the incomplete tail is ignored. With
    `on_message(topic, message)` the messages are handed to it in file order instead of kept (`messages` then
    lists the topics with empty lists): a pass over a long recording in constant memory."""
    out = SessionData()
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    footer_seen: list[bool] = []

    def on_record(rec: Any) -> None:
        if isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            channels[rec.id] = rec
            sch = schemas.get(rec.schema_id)
            out.encodings[rec.topic] = (sch.encoding if sch else "", rec.message_encoding)
            out.messages.setdefault(rec.topic, [])
            if rec.message_encoding == binary.MESSAGE_ENCODING and rec.topic in binary.BINARY_TOPICS:
                out.schemas[rec.topic] = schema_for(rec.topic)   # what the decoded dicts follow
            elif sch is not None and sch.encoding == "jsonschema":
                try:
                    out.schemas[rec.topic] = json.loads(sch.data)
                except (ValueError, UnicodeDecodeError):    # a corrupt schema record (not CRC-protected outside
                    out.undecodable += 1                     # chunks): the topic's messages are still read
        elif isinstance(rec, Message):
            ch = channels.get(rec.channel_id)
            try:
                if ch is not None and ch.message_encoding == binary.MESSAGE_ENCODING:
                    payload = binary.decode(ch.topic, rec.data) if ch.topic in binary.BINARY_TOPICS else None
                else:
                    payload = json.loads(rec.data)
            except (ValueError, UnicodeDecodeError, RecordingError):
                payload = None
            if ch is None or not isinstance(payload, dict):
                out.undecodable += 1
                return
            msg = RecordedMessage(rec.log_time, rec.publish_time, payload, rec.sequence)
            if on_message is not None:
                on_message(ch.topic, msg)
            else:
                out.messages[ch.topic].append(msg)
        elif isinstance(rec, Metadata):
            out.metadata[rec.name] = dict(rec.metadata)
        elif isinstance(rec, Attachment):
            out.attachments[rec.name] = bytes(rec.data)
        elif isinstance(rec, Footer):
            footer_seen.append(True)

    try:
        with open(path, "rb") as f:
            if f.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
                raise RecordingError(f"{path} is not an MCAP file (bad magic)")
            f.seek(0)
            for rec in _records(f, out):
                on_record(rec)
    except OSError as err:
        raise RecordingError(f"cannot read recording {path}: {err}") from err
    out.complete = bool(footer_seen) and out.tail_error is None
    for msgs in out.messages.values():
        msgs.sort(key=lambda m: m.log_time_ns)
    return out

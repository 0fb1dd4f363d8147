"""MCAP session recording: a thread-safe JSON/jsonschema writer with a bounded queue, and a truncation-tolerant reader.

See docs/recording.md for channels, metadata names, drop policy and recovery.
"""
from __future__ import annotations

import atexit
import contextlib
import json
import math
import os
import platform
import queue
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata
from typing import Any, NamedTuple

from mcap.records import Attachment, Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import MCAP0_MAGIC, CompressionType, Writer

from protocol.config import RecordConfig, SeaHilConfig, config_to_toml
from protocol.errors import RecordingError
from protocol.schemas import TOPICS, schema_bytes, schema_name, validate_payload

META_SESSION, META_CONFIG, META_FINAL = "sea-hil.session", "sea-hil.config", "sea-hil.final"
CONFIG_ATTACHMENT = "config.toml"
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
_STOP = object()


class _Sink:
    """Unbuffered file output: every record the MCAP writer emits reaches the OS at once (survives SIGKILL)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self._f = open(path, "wb", buffering=0)
        self.bytes_written = 0

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            n = self._f.write(view)
            view = view[n:]
        self.bytes_written += len(data)
        return len(data)

    def tell(self) -> int:
        return self.bytes_written

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._f.close()


def _finite(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def encode_payload(payload: Mapping[str, Any]) -> bytes:
    """Compact JSON; non-finite floats become null, numpy scalars become Python numbers."""
    def default(o: Any) -> Any:
        if hasattr(o, "item"):
            return _finite(o.item())
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")
    try:
        return json.dumps(payload, separators=(",", ":"), allow_nan=False, default=default).encode()
    except ValueError:
        clean = {k: _finite(v) for k, v in payload.items()}
        return json.dumps(clean, separators=(",", ":"), allow_nan=False, default=default).encode()


def _version(dist: str) -> str:
    try:
        return importlib_metadata.version(dist)
    except importlib_metadata.PackageNotFoundError:
        return "not installed"


def session_metadata(seed: int | None = None, argv: list[str] | None = None) -> dict[str, str]:
    """Host, command line and library versions for the `sea-hil.session` metadata record."""
    return {"python": platform.python_version(), "platform": platform.platform(), "host": socket.gethostname(),
            "pid": str(os.getpid()), "argv": json.dumps(sys.argv if argv is None else argv),
            "seed": "" if seed is None else str(seed), "start_wall_time_ns": str(time.time_ns()),
            "start_monotonic_ns": str(time.monotonic_ns()),
            **{f"version.{d}": _version(d) for d in ("sea-hil", "eclipse-zenoh", "python-can", "mcap", "numpy")}}


def _flatten(prefix: str, d: Mapping[str, Any], out: dict[str, str]) -> dict[str, str]:
    for k, v in d.items():
        if isinstance(v, Mapping):
            _flatten(f"{prefix}{k}.", v, out)
        else:
            out[f"{prefix}{k}"] = json.dumps(v)
    return out


class SessionRecorder:
    """Writes one MCAP session. `record` writes synchronously; `submit` enqueues (bounded, drops when full) for
    the writer thread. Both are thread-safe. `writer_gate` (tests only) holds the writer thread before each item."""

    def __init__(self, path: str | os.PathLike[str], *, compression: str = "zstd", chunk_size_bytes: int = 1 << 20,
                 queue_limit: int = 100_000, flush_period_s: float | None = None,
                 writer_gate: threading.Event | None = None) -> None:
        if compression not in _COMPRESSION:
            raise RecordingError(f"compression must be one of {sorted(_COMPRESSION)}, got {compression!r}")
        try:
            self._sink = _Sink(path)
        except OSError as err:
            raise RecordingError(f"cannot create recording {path}: {err}") from None
        self.path = os.fspath(path)
        self._writer = Writer(self._sink, chunk_size=chunk_size_bytes, compression=_COMPRESSION[compression])
        self._writer.start(profile="", library="sea-hil")
        self._channels: dict[str, int] = {}
        for topic in TOPICS:
            sid = self._writer.register_schema(schema_name(topic), "jsonschema", schema_bytes(topic))
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
        self._lock = threading.Lock()
        self._count_lock = threading.Lock()
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=queue_limit)
        self._gate = writer_gate
        self._flush_period_ns = None if flush_period_s is None else int(flush_period_s * 1e9)
        self._last_flush_ns = time.monotonic_ns()
        self.written = self.dropped = self.chunks_written = self.write_errors = 0
        self.per_topic: dict[str, int] = dict.fromkeys(TOPICS, 0)
        self.last_error: str | None = None
        self.closed_by = "close"
        self._closed = self._closing = False
        self._close_lock = threading.Lock()
        self._writing_thread: int | None = None
        self.deferred_signal: int | None = None
        self._thread = threading.Thread(target=self._run, name="mcap-writer", daemon=True)
        self._thread.start()

    @classmethod
    def from_config(cls, path: str | os.PathLike[str], cfg: RecordConfig, **kw: Any) -> SessionRecorder:
        return cls(path, compression=cfg.compression, chunk_size_bytes=cfg.chunk_size_bytes,
                   queue_limit=cfg.queue_limit, flush_period_s=cfg.flush_period_s or None, **kw)

    # -- metadata and attachments (synchronous) ----------------------------------------------------------------
    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """One MCAP metadata record; non-string values are JSON-encoded."""
        clean = {str(k): v if isinstance(v, str) else json.dumps(v) for k, v in data.items()}
        with self._locked():
            self._writer.add_metadata(name, clean)

    def add_attachment(self, name: str, data: bytes, media_type: str = "text/plain",
                       t_ns: int | None = None) -> None:
        t = time.monotonic_ns() if t_ns is None else t_ns
        with self._locked():
            self._writer.add_attachment(create_time=t, log_time=t, name=name, media_type=media_type, data=data)

    def write_session_header(self, config: SeaHilConfig | None = None, *, seed: int | None = None,
                             argv: list[str] | None = None, extra: Mapping[str, Any] | None = None) -> None:
        """Metadata `sea-hil.session` (+ `extra`), `sea-hil.config` and attachment `config.toml`."""
        self.add_metadata(META_SESSION, {**session_metadata(seed, argv), **(extra or {})})
        if config is not None:
            self.add_metadata(META_CONFIG, _flatten("", config.model_dump(mode="json"), {}))
            self.add_attachment(CONFIG_ATTACHMENT, config_to_toml(config).encode(), "application/toml")

    # -- messages ------------------------------------------------------------------------------------------------
    def record(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any]) -> None:
        """Validate and write one message now (`RecordingError` on bad input or after close)."""
        validate_payload(topic, payload)
        self._write(topic, log_time_ns, publish_time_ns, encode_payload(payload))

    def submit(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any]) -> bool:
        """Validate, encode and enqueue; returns False (and counts `dropped`) when the queue is full."""
        validate_payload(topic, payload)
        if self._closing:
            raise RecordingError("recorder is closed")
        try:
            self._queue.put_nowait((topic, log_time_ns, publish_time_ns, encode_payload(payload)))
            return True
        except queue.Full:
            with self._count_lock:
                self.dropped += 1
            return False

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        with self._lock:
            if self._closed:
                raise RecordingError("recorder is closed")
            yield

    def _write(self, topic: str, log_time_ns: int, publish_time_ns: int, data: bytes) -> None:
        with self._locked():
            self._writing_thread = threading.get_ident()
            try:
                before = self._sink.bytes_written
                self._writer.add_message(self._channels[topic], log_time_ns, data, publish_time_ns)
                self.written += 1
                self.per_topic[topic] += 1
                now = time.monotonic_ns()
                if self._flush_period_ns is not None and now - self._last_flush_ns >= self._flush_period_ns:
                    self._writer.flush()
                if self._sink.bytes_written != before:
                    self.chunks_written += 1
                    self._last_flush_ns = now
            finally:
                self._writing_thread = None
        if self.deferred_signal is not None and threading.current_thread() is threading.main_thread():
            raise SystemExit(128 + self.deferred_signal)

    def _run(self) -> None:
        while True:
            if self._gate is not None:
                self._gate.wait()
            item = self._queue.get()
            if item is _STOP:
                return
            try:
                self._write(*item)
            except Exception as err:  # noqa: BLE001 - the writer thread must survive (counted, reported)
                self.write_errors += 1
                self.last_error = f"{type(err).__name__}: {err}"

    def counters(self) -> dict[str, int]:
        return {"written": self.written, "dropped": self.dropped, "chunks_written": self.chunks_written,
                "write_errors": self.write_errors, "queued": self._queue.qsize()}

    def close(self, final_stats: Mapping[str, Any] | None = None) -> None:
        """Drain the queue, write `sea-hil.final` metadata (counters + `final_stats`), summary and index. Idempotent."""
        with self._close_lock:
            if self._closing:
                return
            self._closing = True
        self._queue.put(_STOP)
        self._thread.join()
        while not self._queue.empty():  # raced in after the stop marker: never written
            self._queue.get_nowait()
            self.dropped += 1
        final = {**self.counters(), "closed_by": self.closed_by, "last_error": self.last_error or "",
                 **{f"messages.{t}": n for t, n in self.per_topic.items()}, **(final_stats or {})}
        with self._lock:
            self._closed = True
            try:
                self._writer.add_metadata(META_FINAL, {k: v if isinstance(v, str) else json.dumps(v)
                                                       for k, v in final.items()})
                self._writer.finish()
            finally:
                self._sink.close()

    def __enter__(self) -> SessionRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def install_finalizer(recorder: SessionRecorder,
                      signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)) -> Callable[[], None]:
    """Make SIGINT/SIGTERM end the process with SystemExit(128+signum) after the recording is finalised (via
    atexit and any enclosing `with`). Call from the main thread; returns a function restoring the old handlers."""
    def handler(signum: int, _frame: object) -> None:
        recorder.closed_by = signal.Signals(signum).name
        if recorder._writing_thread == threading.get_ident():
            recorder.deferred_signal = signum  # inside a write: raise once the writer state is consistent
            return
        raise SystemExit(128 + signum)

    previous = {s: signal.signal(s, handler) for s in signals}
    atexit.register(recorder.close)

    def uninstall() -> None:
        for s, h in previous.items():
            signal.signal(s, h)
        atexit.unregister(recorder.close)
    return uninstall


class RecordedMessage(NamedTuple):
    log_time_ns: int
    publish_time_ns: int
    payload: dict[str, Any]


@dataclass
class SessionData:
    """Everything read back from a session file. `complete` (footer and closing magic read) is False for a
    truncated (recovered) file; `tail_error` then says why reading stopped, `chunks` counts complete chunks."""
    messages: dict[str, list[RecordedMessage]] = field(default_factory=dict)
    schemas: dict[str, dict[str, Any]] = field(default_factory=dict)
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


def read_session(path: str | os.PathLike[str]) -> SessionData:
    """Read all messages (per topic, log_time order), schemas, metadata and attachments. Works on truncated files
    (no summary/footer after SIGKILL): every complete chunk is read, the incomplete tail is ignored."""
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
            if sch is not None and sch.encoding == "jsonschema":
                out.schemas[rec.topic] = json.loads(sch.data)
        elif isinstance(rec, Message):
            ch = channels.get(rec.channel_id)
            try:
                payload = json.loads(rec.data)
            except (ValueError, UnicodeDecodeError):
                payload = None
            if ch is None or not isinstance(payload, dict):
                out.undecodable += 1
                return
            out.messages[ch.topic].append(RecordedMessage(rec.log_time, rec.publish_time, payload))
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
            try:
                for rec in StreamReader(f, emit_chunks=True).records:
                    if isinstance(rec, Chunk):
                        inner = breakup_chunk(rec, validate_crc=True)  # all-or-nothing per chunk
                        out.chunks += 1
                        for r in inner:
                            on_record(r)
                    else:
                        on_record(rec)
            except Exception as err:  # noqa: BLE001 - any failure past the last good record is the torn tail
                out.tail_error = f"{type(err).__name__}: {err}"
    except OSError as err:
        raise RecordingError(f"cannot read recording {path}: {err}") from None
    out.complete = bool(footer_seen) and out.tail_error is None
    for msgs in out.messages.values():
        msgs.sort(key=lambda m: m.log_time_ns)
    return out

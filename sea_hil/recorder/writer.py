"""MCAP session recording: a thread-safe writer with a bounded queue and a signal-safe finaliser. Messages are JSON
(schema encoding jsonschema), the high-rate CAN channels protobuf (`sea_hil.recorder.binary`); `write_encoded` writes
many encoded messages under one lock through `sea_hil.recorder.mcap_bulk.BulkWriter` (what the recorder process
does with the CAN tap's `encode`), `record_batch` checks and encodes payload dicts first.

Metadata/header helpers live in `sea_hil.recorder.meta`, the reader in `sea_hil.recorder.reader`. `RecordSink` is
what a session needs of a recorder: this `SessionRecorder`, or `sea_hil.recorder.process.RecorderProcess` (the
same calls, written by a child process). See docs/recording.md for channels, metadata names, drop policy and
recovery.
"""
from __future__ import annotations

import atexit
import contextlib
import json
import os
import queue
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import IO, Any, Protocol, cast

from mcap.writer import CompressionType

from sea_hil.config.comms import RecordConfig
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import RecordingError
from sea_hil.recorder.mcap_bulk import BulkWriter
from sea_hil.recorder.meta import (
    META_FINAL,
    write_session_header,
)
from sea_hil.recorder.schemas import TOPICS, encodings, message_bytes, schema_bytes, schema_name

__all__ = ["SessionRecorder", "install_finalizer"]
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



class RecordSink(Protocol):
    """Where a session's messages go (`SessionRecorder`, `RecorderProcess`): validated at the call, written in
    order; `submit` may drop (counted) when the writer falls behind, `record` does not."""

    def record(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any],
               sequence: int = 0) -> None: ...

    def submit(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any],
               sequence: int = 0) -> bool: ...

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None: ...

    def write_session_header(self, config: SeaHilConfig | None = None, *, seed: int | None = None,
                             argv: list[str] | None = None, extra: Mapping[str, Any] | None = None) -> None: ...

    def counters(self) -> dict[str, int]: ...

    def close(self, final_stats: Mapping[str, Any] | None = None) -> None: ...


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
            raise RecordingError(f"cannot create recording {path}: {err}") from err
        self.path = os.fspath(path)
        self._writer = BulkWriter(cast(IO[bytes], self._sink),   # a file to the writer (write, tell, flush, close)
                                  chunk_size=chunk_size_bytes, compression=_COMPRESSION[compression])
        self._writer.start(profile="", library="sea-hil")
        self._channels: dict[str, int] = {}
        schema_ids: dict[tuple[str, str, bytes], int] = {}   # one schema record per distinct schema
        for topic in TOPICS:
            schema_encoding, message_encoding = encodings(topic)
            key = (schema_name(topic), schema_encoding, schema_bytes(topic))
            if key not in schema_ids:
                schema_ids[key] = self._writer.register_schema(key[0], schema_encoding, key[2])
            self._channels[topic] = self._writer.register_channel(topic, message_encoding, schema_ids[key])
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
        write_session_header(self, config, seed=seed, argv=argv, extra=extra)

    # -- messages ------------------------------------------------------------------------------------------------
    def record(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any],
               sequence: int = 0) -> None:
        """Validate and write one message now (`RecordingError` on bad input or after close). `sequence` is the
        sender's sequence number (MCAP `sequence`, u32; 0 when the message has none)."""
        self._write(topic, log_time_ns, publish_time_ns, message_bytes(topic, payload), sequence)

    def record_batch(self, records: Iterable[tuple[str, int, int, Mapping[str, Any], int]]) -> int:
        """Check, encode and write many (topic, log time, publish time, payload, sequence) messages now, under one
        lock and one bulk append; a bad one is not written but counted (`write_errors`, `last_error`), as the
        writer thread counts its failures. -> messages written."""
        items = []
        for topic, log_time_ns, publish_time_ns, payload, sequence in records:
            try:
                items.append((topic, log_time_ns, publish_time_ns, message_bytes(topic, payload), sequence))
            except RecordingError as err:
                self.write_errors += 1
                self.last_error = str(err)
        return self.write_encoded(items)

    def write_encoded(self, items: Sequence[tuple[str, int, int, bytes, int]]) -> int:
        """Write many (topic, log time, publish time, encoded data, sequence) messages now (data as
        `schemas.message_bytes` encodes it: the CAN tap's `encode`), under one lock and one bulk append; one with
        an unknown topic or a sequence that is not a u32 is not written but counted (`write_errors`). -> messages
        written."""
        channels = self._channels
        try:
            batch = [(channels[topic], log, data, pub, seq) for topic, log, pub, data, seq in items
                     if 0 <= seq < 1 << 32]
        except KeyError:
            batch = []
        if len(batch) != len(items):   # the rare bad one: count it, write the rest
            items = self._valid(items)
            batch = [(channels[topic], log, data, pub, seq) for topic, log, pub, data, seq in items]
        if not batch:
            return 0
        with self._locked():
            self._writing_thread = threading.get_ident()
            try:
                before, chunks_before = self._sink.bytes_written, self._writer.chunk_count
                self._writer.add_messages(batch)
                self.written += len(batch)
                per_topic = self.per_topic
                for it in items:
                    per_topic[it[0]] += 1
                now = time.monotonic_ns()
                if self._flush_period_ns is not None and now - self._last_flush_ns >= self._flush_period_ns:
                    self._writer.flush()
                if self._sink.bytes_written != before:
                    chunks_after = self._writer.chunk_count
                    self.chunks_written += 1 if chunks_before is None or chunks_after is None \
                        else chunks_after - chunks_before
                    self._last_flush_ns = now
            finally:
                self._writing_thread = None
        if self.deferred_signal is not None and threading.current_thread() is threading.main_thread():
            raise SystemExit(128 + self.deferred_signal)
        return len(batch)

    def _valid(self, items: Sequence[tuple[str, int, int, bytes, int]]) -> list[tuple[str, int, int, bytes, int]]:
        """The items `write_encoded` can write; each other one counted in `write_errors`."""
        ok = []
        for it in items:
            topic, seq = it[0], it[4]
            if topic not in self._channels:
                self.last_error = f"unknown recording topic {topic!r}"
            elif not 0 <= seq < 1 << 32:
                self.last_error = f"{topic}: sequence {seq} is not a u32"
            else:
                ok.append(it)
                continue
            self.write_errors += 1
        return ok

    def submit(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any],
               sequence: int = 0) -> bool:
        """Validate, encode and enqueue; returns False (and counts `dropped`) when the queue is full."""
        return self.submit_encoded(topic, log_time_ns, publish_time_ns, message_bytes(topic, payload), sequence)

    def submit_encoded(self, topic: str, log_time_ns: int, publish_time_ns: int, data: bytes,
                       sequence: int = 0) -> bool:
        """`submit` of a message already encoded (`write_encoded`'s items: the CAN tap's `encode`)."""
        if topic not in self._channels:
            raise RecordingError(f"unknown recording topic {topic!r}")
        if self._closing:
            raise RecordingError("recorder is closed")
        try:
            self._queue.put_nowait((topic, log_time_ns, publish_time_ns, data, sequence))
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

    def _write(self, topic: str, log_time_ns: int, publish_time_ns: int, data: bytes, sequence: int = 0) -> None:
        if not 0 <= sequence < 1 << 32:
            raise RecordingError(f"{topic}: sequence {sequence} is not a u32")
        with self._locked():
            self._writing_thread = threading.get_ident()
            try:
                before = self._sink.bytes_written
                self._writer.add_message(self._channels[topic], log_time_ns, data, publish_time_ns, sequence)
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
        with self._lock:
            self._closed = True
            try:
                before = self._sink.bytes_written
                self._writer.flush()   # the open chunk goes out first, so `chunks_written` counts it
                self.chunks_written += self._sink.bytes_written != before
                final = {**self.counters(), "closed_by": self.closed_by, "last_error": self.last_error or "",
                         **{f"messages.{t}": n for t, n in self.per_topic.items()}, **(final_stats or {})}
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


"""The MCAP writer in a child process: CAN decoding, encoding and MCAP writing off the caller's GIL.

`RecorderProcess(path, cfg)` starts ``python -m sea_hil.recorder.process PATH RECORD_CONFIG_JSON`` and offers the
recorder interface the recorder node and `sea-hil run` use (`submit`, `record`, `add_metadata`, `add_attachment`,
`write_session_header`, `close`) plus `submit_can(raw_frame)` and `submit_can_batch(frames)`: raw frames are shipped
as plain tuples (10x cheaper to pickle than `RawFrame`s: 0.2 vs 1.5 us per frame) and decoded and encoded in the
child (`sea_hil.recorder.can_tap.CanTap.encode`, exactly what the in-process recorder writes), which writes each
batch's messages in one `SessionRecorder.write_encoded` call. Operations are batched (`batch_ops` frames or messages) into
length-prefixed pickles on the child's stdin (a private pipe between two processes of
the same program). `time_base` (`sea_hil.recorder.clock`) is the log-time clock of the child's CAN tap. A child that
dies is reported by `close` (`RecordingError`); operations that could not be
delivered are counted in `dropped`, never raised into the submitting node.
"""
from __future__ import annotations

import logging
import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from typing import IO, TYPE_CHECKING, Any, BinaryIO

from sea_hil.config.comms import RecordConfig
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import RecordingError
from sea_hil.live.feed import LiveSpec, start_live_feed
from sea_hil.live.link import live_child_argv
from sea_hil.recorder.can_tap import CanTap, Encoded, RawFrame
from sea_hil.recorder.clock import TimeBase, check_time_base
from sea_hil.recorder.meta import CONFIG_ATTACHMENT, write_session_header
from sea_hil.recorder.schemas import encoded_payload, message_bytes, message_payload, validate_payload
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.recorder.zenoh_tap import ZenohTap

if TYPE_CHECKING:
    from sea_hil.live.feed import LiveFeed

log = logging.getLogger("sea_hil.record")
_LEN = struct.Struct("<I")
CAN, CANS, ZENOH, RECORD, METADATA, ATTACHMENT, CLOSE = "c", "n", "z", "r", "m", "a", "x"


class RecorderProcess:
    """Parent-side proxy of a `SessionRecorder` running in a child process. Thread-safe."""

    def __init__(self, path: str | os.PathLike[str], cfg: RecordConfig, *, batch_ops: int = 512,
                 close_timeout_s: float = 300.0, nice: int = 10, idle: bool = False,
                 time_base: TimeBase = "wall", live: LiveSpec | None = None) -> None:
        """`live`: the child also serves the live view (`sea_hil.live`), and `self.live` is the parent's end of its
        notice pipe."""
        self.path = os.fspath(path)
        self.batch_ops = batch_ops
        self.close_timeout_s = close_timeout_s
        argv, self.live = live_child_argv(live)
        self._proc = subprocess.Popen([sys.executable, "-m", "sea_hil.recorder.process", self.path,
                                       cfg.model_dump_json(), str(nice), str(int(idle)), check_time_base(time_base),
                                       *argv], stdin=subprocess.PIPE,
                                      pass_fds=() if self.live is None else (self.live.write_fd,))
        if self.live is not None:
            self.live.child_started()
        self._lock = threading.Lock()
        self._pending: list[tuple[Any, ...]] = []
        self._pending_n = 0   # frames and messages in `_pending`
        self._closed = False
        self.sent_ops = self.dropped = 0
        # batches go to the child's stdin from a feeder thread: a child that falls behind (it runs on idle CPU time
        # only, and may serve a live view) makes the backlog grow here instead of blocking the taps that submit (a
        # blocked tap would stop draining its Zenoh subscriber and stall the session's Zenoh runtime)
        self._out: queue.SimpleQueue[tuple[bytes, int] | threading.Event | None] = queue.SimpleQueue()
        self.backlog_max = 0
        self._backlog = 0
        self._feeder = threading.Thread(target=self._feed, name="recorder-feed", daemon=True)
        self._feeder.start()

    # -- the recorder interface ----------------------------------------------------------------------------------
    def submit_can(self, frame: RawFrame) -> None:
        """Queue one raw frame (decoded and written by the child)."""
        self._put((CAN, tuple(frame)))

    def submit_can_batch(self, frames: list[tuple[Any, ...]]) -> None:
        """Queue many raw frames at once, each a `RawFrame` or the plain tuple of its fields (what the CAN tap
        hands over once per wake-up)."""
        if frames:
            self._put((CANS, frames), len(frames))

    def submit_zenoh(self, key: str, data: bytes, rx_wall_ns: int) -> None:
        """Queue one Zenoh message as it came (decoded, counted and written by the child's Zenoh tap)."""
        self._put((ZENOH, key, data, rx_wall_ns))

    def submit(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any],
               sequence: int = 0) -> bool:
        """Validate here (bad input fails at its source) and queue; False once the child is gone."""
        validate_payload(topic, payload)
        return self._put((RECORD, topic, log_time_ns, publish_time_ns, dict(payload), sequence))

    def record(self, topic: str, log_time_ns: int, publish_time_ns: int, payload: Mapping[str, Any],
               sequence: int = 0) -> None:
        self.submit(topic, log_time_ns, publish_time_ns, payload, sequence)
        self.flush()

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        self._put((METADATA, name, dict(data)))
        self.flush()

    def add_attachment(self, name: str, data: bytes, media_type: str = "text/plain",
                       t_ns: int | None = None) -> None:
        self._put((ATTACHMENT, name, bytes(data), media_type, t_ns))
        self.flush()

    def write_session_header(self, config: SeaHilConfig | None = None, *, seed: int | None = None,
                             argv: list[str] | None = None, extra: Mapping[str, Any] | None = None) -> None:
        write_session_header(self, config, seed=seed, argv=argv, extra=extra)

    def flush(self, wait: bool = True) -> None:
        """Hand what is batched to the feeder; with `wait`, return once it is written to the child (or counted as
        dropped). The taps flush without waiting (they must never block on a slow child)."""
        with self._lock:
            self._flush_locked()
        if wait:
            done = threading.Event()
            self._out.put(done)
            done.wait(self.close_timeout_s)

    def close(self, final_stats: Mapping[str, Any] | None = None) -> None:
        """Deliver everything, let the child write `sea-hil.final` and the index, wait for it. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._pending.append((CLOSE, {**(final_stats or {}), "recorder_dropped_ops": self.dropped}))
            self._flush_locked()
            self._closed = True
        self._out.put(None)               # the feeder writes what is queued, then stops
        self._feeder.join(self.close_timeout_s)
        try:
            self._stdin.close()
        except OSError:
            pass
        try:
            code = self._proc.wait(timeout=self.close_timeout_s)
            if self.live is not None:
                self.live.close()
        except subprocess.TimeoutExpired as err:
            self._proc.kill()
            self._proc.wait()
            raise RecordingError(f"recorder process did not finish {self.path} in {self.close_timeout_s} s") from err
        if code != 0:
            raise RecordingError(f"recorder process for {self.path} exited with status {code}")

    def counters(self) -> dict[str, int]:
        return {"sent_ops": self.sent_ops, "dropped": self.dropped, "backlog_max_batches": self.backlog_max}

    # -- transport -----------------------------------------------------------------------------------------------
    @property
    def _stdin(self) -> IO[bytes]:
        assert self._proc.stdin is not None
        return self._proc.stdin

    def _put(self, op: tuple[Any, ...], n: int = 1) -> bool:
        """Queue `op` (`n` frames or messages: what `dropped` and `sent_ops` count)."""
        with self._lock:
            if self._closed:
                self.dropped += n
                return False
            self._pending.append(op)
            self._pending_n += n
            if self._pending_n >= self.batch_ops:
                self._flush_locked()
        return True

    def _flush_locked(self) -> None:
        if not self._pending or self._closed:
            return
        ops, n, self._pending, self._pending_n = self._pending, self._pending_n, [], 0
        self._backlog += 1
        self.backlog_max = max(self.backlog_max, self._backlog)
        self._out.put((pickle.dumps(ops, protocol=pickle.HIGHEST_PROTOCOL), n))

    def _feed(self) -> None:
        """The feeder thread: write queued batches to the child until the end marker."""
        while (item := self._out.get()) is not None:
            if isinstance(item, threading.Event):   # a waiting `flush`: everything before it is written
                item.set()
                continue
            blob, n = item
            self._backlog -= 1
            try:
                self._stdin.write(_LEN.pack(len(blob)) + blob)
                self._stdin.flush()
                self.sent_ops += n
            except (OSError, ValueError) as err:   # child gone: count, keep the callers alive
                self.dropped += n
                log.error("recorder process pipe: %s", err)


def _apply(rec: SessionRecorder, tap: CanTap, ops: list[tuple[Any, ...]], live: LiveFeed | None = None,
           cpu_from_s: float | None = None, ztap: ZenohTap | None = None) -> bool:
    """Apply one batch in the child; True when the batch closed the recording. `live` sees what was written.
    Messages (encoded frames and Zenoh messages, records) are collected and written in one `write_encoded` per run
    of them. `cpu_from_s`: the child's process CPU time when its work began (the final stats get `recorder_cpu_s`).
    `ztap`: the child's Zenoh tap (a new one if not given: its counts then stay out of the final stats)."""
    ztap = ztap or ZenohTap(time_base=tap.time_base)
    batch: list[Encoded] = []   # (topic, log time, publish time, encoded data, sequence)

    def write() -> None:
        try:
            rec.write_encoded(batch)
        except RecordingError as err:   # written after close: counted, as one bad message is
            rec.write_errors += 1
            rec.last_error = str(err)
        if live is not None:
            for topic, log_time_ns, _, data, _ in batch:
                live.feed(topic, log_time_ns, message_payload(topic, data))
        batch.clear()

    for op in ops:
        kind = op[0]
        if kind == CANS:
            batch += tap.encode(op[1])
            continue
        if kind == CAN:
            batch += tap.encode((op[1],))
            continue
        if kind == ZENOH:
            for r in ztap.take(op[1], op[2], op[3]):
                try:   # from the wire: checked as it is encoded
                    batch.append((r.topic, r.log_time_ns, r.publish_time_ns, message_bytes(r.topic, r.payload),
                                  r.sequence))
                except RecordingError as err:
                    rec.write_errors += 1
                    rec.last_error = str(err)
            continue
        if kind == RECORD:
            try:   # checked by the parent (`submit`): only encoded here
                batch.append((op[1], op[2], op[3], encoded_payload(op[1], op[4]), op[5]))
            except RecordingError as err:
                rec.write_errors += 1
                rec.last_error = str(err)
            continue
        if batch:
            write()
        try:
            if kind == METADATA:
                rec.add_metadata(*op[1:])
            elif kind == ATTACHMENT:
                rec.add_attachment(*op[1:])
                if op[1] == CONFIG_ATTACHMENT:   # the session's drive limits: each latch explained in /log/faults
                    tap.configure(bytes(op[2]).decode("utf-8", "replace"))
                    if live is not None and tap.canopen is not None:   # a cia402 bus: driver state by statusword
                        live.view.follow_canopen(tap.canopen.fresh())
            elif kind == CLOSE:
                live_counts = live.counters() if live is not None else {}
                rec.close(final_stats={**op[1], **tap.counters(), **ztap.counters(), **live_counts,
                                       **_cpu(cpu_from_s)})   # the child's CAN and Zenoh counts rule
                return True
        except RecordingError as err:   # one bad message: counted in the file's final metadata, keep going
            rec.write_errors += 1
            rec.last_error = str(err)
    if batch:
        write()
    return False


def _cpu(cpu_from_s: float | None) -> dict[str, float]:
    """`recorder_cpu_s`: the child's CPU time (process, user + system) from `cpu_from_s` on: what recording the
    session's messages cost, start-up excluded (bench/bench_cpu_per_sample.py reads it)."""
    return {} if cpu_from_s is None else {"recorder_cpu_s": round(time.process_time() - cpu_from_s, 3)}


def _read_exact(f: BinaryIO, n: int) -> bytes | None:
    buf = f.read(n)
    return buf if buf is not None and len(buf) == n else None


def _idle_policy() -> None:
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError) as err:   # not Linux, or not permitted here: nice alone
        log.info("recorder process keeps the normal policy: %s", err)


def child_main(path: str, cfg_json: str, stream: BinaryIO, nice: int = 0, idle: bool = False,
               time_base: TimeBase = "wall", live_json: str | None = None) -> int:
    """The child: apply batches from `stream` until CLOSE; end of stream without CLOSE still finalises the file.
    `nice` > 0 lowers its CPU priority: recording is background work that must not delay the nodes. `idle` (real-time
    sessions) also asks for Linux's SCHED_IDLE policy, so it runs only on otherwise idle CPU time: with nice 10 alone
    its decoding bursts still took a core from the 1 kHz nodes (closed-loop latency p99 7.3-9.3 ms; with SCHED_IDLE
    1.2-2.6 ms). Lockstep keeps nice alone: there the nodes keep the CPUs busy and an idle-policy recorder would only
    catch up at the end (5.1 s instead of ~4 s per cycle). `live_json` (a `LiveSpec`): also serve the live view
    from here, on the same low priority, off the nodes' processes."""
    if nice > 0:
        os.nice(nice)
    if idle:
        _idle_policy()
    rec = SessionRecorder.from_config(path, RecordConfig.model_validate_json(cfg_json))
    tap, ztap = CanTap(time_base=time_base), ZenohTap(time_base=time_base)
    live = None
    if live_json is not None:
        live = start_live_feed(live_json)
    cpu_from_s = None
    try:
        while (head := _read_exact(stream, _LEN.size)) is not None:
            blob = _read_exact(stream, _LEN.unpack(head)[0])
            if blob is None:
                break
            if cpu_from_s is None:
                cpu_from_s = time.process_time()
            if _apply(rec, tap, pickle.loads(blob), live, cpu_from_s, ztap):
                return 0
        rec.closed_by = "eof"   # the parent went away without closing: finalise what arrived
        rec.close(final_stats={**tap.counters(), **ztap.counters(), **_cpu(cpu_from_s)})
        return 0
    finally:
        if live is not None:
            live.close()


if __name__ == "__main__":
    sys.exit(child_main(sys.argv[1], sys.argv[2], sys.stdin.buffer, int(sys.argv[3]) if len(sys.argv) > 3 else 0,
                        len(sys.argv) > 4 and sys.argv[4] == "1",
                        check_time_base(sys.argv[5]) if len(sys.argv) > 5 else "wall",
                        sys.argv[6] if len(sys.argv) > 6 else None))

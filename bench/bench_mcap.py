"""Figure 7: MCAP recorder throughput (messages/s) and file size per session minute.

Run: python -m bench.bench_mcap [--runs 3] [--session FILE.mcap] [--json OUT]
The message mix is a real session's: `--session` (a `sea-hil run` recording) or, by default, a fresh
`sea-hil run --controller et --cycles 1` (real time). Throughput: every message of that session is replayed into a
new `sea_hil.recorder.writer.SessionRecorder` (config compression/chunking, queue large enough that nothing drops) as fast
as possible: `submit` on this thread (validate + JSON encode), the writer thread compressing and writing; the time
runs from the first submit until `close()` returned. Baseline: the session's own message rate (what a live
recorder must sustain). File size per minute = size of the recorded session file / its time span x 60.
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

from bench.benchlib import bench_args, emit, record, sea_hil_run, sea_hil_run_cmd
from sea_hil.config.loader import load_config
from sea_hil.recorder.reader import RecordedMessage, read_session
from sea_hil.recorder.writer import SessionRecorder


def replay(messages: list[tuple[str, RecordedMessage]], out: Path) -> tuple[float, int, int]:
    """Write `messages` into a new recording at `out`; returns (seconds, written, dropped)."""
    cfg = load_config().record
    rec = SessionRecorder(out, compression=cfg.compression, chunk_size_bytes=cfg.chunk_size_bytes,
                          queue_limit=len(messages) + 16, flush_period_s=cfg.flush_period_s or None)
    t0 = time.perf_counter()
    for topic, m in messages:
        rec.submit(topic, m.log_time_ns, m.publish_time_ns, m.payload)
    rec.close()
    return time.perf_counter() - t0, rec.written, rec.dropped


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=3)
    ap.add_argument("--session", type=Path, metavar="FILE", help="recording whose messages are replayed")
    args = ap.parse_args(argv)
    runs = 1 if args.quick else args.runs
    with tempfile.TemporaryDirectory(prefix="bench-mcap-") as tmp:
        src = args.session
        source = f"{src}" if src else sea_hil_run_cmd("et", args.quick)
        if src is None:
            # quick mode records a lockstep session (faster on a busy machine); the figure uses real time
            sea_hil_run(Path(tmp) / "session", controller="et", lockstep=args.quick)
            src = Path(tmp) / "session" / "session.mcap"
        t0 = time.perf_counter()
        data = read_session(src)
        read_s = time.perf_counter() - t0
        msgs = sorted(((t, m) for t, ms in data.messages.items() for m in ms), key=lambda tm: tm[1].log_time_ns)
        span_s = (msgs[-1][1].log_time_ns - msgs[0][1].log_time_ns) * 1e-9 if len(msgs) > 1 else float("nan")
        size_b = os.path.getsize(src)
        rates, details = [], []
        for i in range(runs):
            secs, written, dropped = replay(msgs, Path(tmp) / f"replay{i}.mcap")
            rates.append(written / secs)
            details.append({"run": i + 1, "messages": len(msgs), "written": written, "dropped": dropped,
                            "seconds": secs, "msgs_per_s": written / secs,
                            "replay_file_bytes": os.path.getsize(Path(tmp) / f"replay{i}.mcap")})
            print(f"run {i + 1}/{runs}: {written} msgs in {secs:.2f} s = {written / secs:,.0f} msgs/s, dropped "
                  f"{dropped}", flush=True)
    need = len(msgs) / span_s
    mb_per_min = size_b / span_s * 60 / 1e6
    topics = ", ".join(f"{t} {len(m)}" for t, m in data.messages.items() if m)
    rec = record("7", "MCAP recorder throughput", runs=runs,
                 metric="messages/s replaying a real session's messages through SessionRecorder (submit -> close)",
                 unit="msgs/s", per_run=rates, p99=float("nan"), baseline=need,
                 baseline_label="message rate of the recorded session (a live recorder must sustain it)",
                 goal="throughput > session message rate, no drops",
                 goal_met=min(rates) > need and all(d["dropped"] == 0 for d in details), details=details,
                 notes=f"source: {source}; {len(msgs)} msgs over {span_s:.1f} s ({topics}); reading it back with "
                       f"read_session: {len(msgs) / read_s:,.0f} msgs/s.")
    size = record("7b", "MCAP file size per session minute", runs=1, metric="bytes of the session file / its time "
                  "span x 60", unit="MB/min", per_run=[mb_per_min], p99=float("nan"),
                  goal="(informative)", details=[{"file_bytes": size_b, "span_s": span_s,
                                                  "compression": load_config().record.compression}],
                  notes=f"source: {source}; {size_b / 1e6:.2f} MB for {span_s:.1f} s, zstd, every CAN frame raw and "
                        "decoded + every Zenoh message.")
    emit([rec, size], args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

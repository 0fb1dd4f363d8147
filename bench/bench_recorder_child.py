"""CPU of the recorder child's work per CAN frame: unpickle a batch, decode, encode, write MCAP (issue 33).

Run: python -m bench.bench_recorder_child [--runs 3] [--samples 5000] [--json OUT]
The frames are what one classic-CAN limb sends per sample (FEEDBACK_ANGLE, FEEDBACK_JOINT1, FEEDBACK_JOINT2,
VOLTAGE_CMD; values varying per sample), shipped as the CAN tap ships them (`CANS` operations of 64 frames, 8 per
pickle) and applied by `sea_hil.recorder.process._apply` into a zstd `SessionRecorder` in a temporary directory, in
this one process, so the figure is the child's own work without the session around it (no pipe, no wake-ups; the
real session's child costs more: bench/bench_cpu_per_sample.py). Printed: CPU us per frame (min over runs) and per
limb-sample at 4 frames. Process CPU time, not wall time: on a shared host it still inflates with load (cache).
"""
from __future__ import annotations

import os
import pickle
import sys
import tempfile
import time
from pathlib import Path

from bench.benchlib import bench_args, emit, record
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import T_US_MODULUS, FeedbackAngle, FeedbackJoint1, FeedbackJoint2, VoltageCmd
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.process import CANS, _apply
from sea_hil.recorder.writer import SessionRecorder

FRAMES_PER_SAMPLE = 4


def frames(samples: int) -> list[tuple]:
    codec = SeaCodec(fd=None)
    out: list[tuple] = []
    for k in range(samples):
        x = (k % 1000) / 1000
        for obj in (FeedbackAngle(1, k % 256, 1000 * k % T_US_MODULUS, (0.3 * x, -0.2 * x)),
                    FeedbackJoint1(1, k % 256, 0.5 - x, 1e-3 * x, -1e-3 * x),
                    FeedbackJoint2(1, k % 256, x - 0.5, -1e-3 * x, 1e-3 * x),
                    VoltageCmd(1, (20 * x - 10, 10 - 20 * x), k % 256)):
            out.append(tuple(RawFrame.of(1_700_000_000 * 10**9 + 250_000 * len(out), codec.encode(obj))))
    return out


def one_run(blobs: list[bytes], n_frames: int) -> float:
    """CPU us per frame of applying every blob."""
    with tempfile.TemporaryDirectory() as tmp:
        rec = SessionRecorder(Path(tmp) / "b.mcap", flush_period_s=1.0)
        tap = CanTap()
        t0 = time.process_time()
        for b in blobs:
            _apply(rec, tap, pickle.loads(b))
        rec.close()
        dt = time.process_time() - t0
    return 1e6 * dt / n_frames


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=3)
    ap.add_argument("--samples", type=int, default=5000)
    args = ap.parse_args(argv)
    if args.quick:
        args.runs, args.samples = 1, 500
    fr = frames(args.samples)
    ops = [(CANS, fr[i:i + 64]) for i in range(0, len(fr), 64)]
    blobs = [pickle.dumps(ops[i:i + 8], protocol=pickle.HIGHEST_PROTOCOL) for i in range(0, len(ops), 8)]
    one_run(blobs[:2], 1)   # warm-up (imports, first chunk)
    per_frame = [one_run(blobs, len(fr)) for _ in range(args.runs)]
    load = os.getloadavg()[0]
    print(f"{len(fr)} frames, {args.runs} run(s), load average {load:.1f}: CPU us per frame "
          f"{min(per_frame):.1f}-{max(per_frame):.1f}, per limb-sample ({FRAMES_PER_SAMPLE} frames) "
          f"{FRAMES_PER_SAMPLE * min(per_frame):.0f}-{FRAMES_PER_SAMPLE * max(per_frame):.0f}")
    if args.json:
        emit([record("7c", "recorder child: CPU per CAN frame (decode, encode, MCAP write)", runs=args.runs,
                     unit="us/frame", per_run=per_frame, p99=float("nan"), goal="(informative)",
                     metric="process CPU time of `_apply` over pickled batches of one limb's frames, per frame",
                     notes=f"load average {load:.1f}")], args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

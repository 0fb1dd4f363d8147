"""CPU of the recorder child's work per limb-sample: unpickle, decode, encode, write MCAP (issue 33).

Run: python -m bench.bench_recorder_child [--runs 3] [--samples 5000] [--limbs 1] [--compare PYTHON] [--json OUT]
The input is what a real-time `sea-hil run` ships to its recorder child (`sea_hil.recorder.process`), built here
deterministically: the session's config attachment first (so, as in a session, a drive's latch would be explained
from the measured values the tap keeps), then per 10 ms tap wake-up (`tap_batch_s`) one `CANS` operation with
that wake-up's frames of every limb (per sample FEEDBACK_ANGLE, FEEDBACK_JOINT1, FEEDBACK_JOINT2 and a VOLTAGE_CMD;
a HEARTBEAT every 100 samples; values varying per sample) and the Zenoh messages the tap takes at the rates of a
1-limb ET session (per 1000 samples 100 tracking records, 28 trigger events: a state, its tracking record, a
setpoint), as the checkout's tap submits them (as they came, or the records it makes of them), batched into
length-prefixed pickles of >= 512 operations as `RecorderProcess` sends them. `child_main` applies the stream from memory into a zstd recording in a temporary directory, in this
one process, so the figure is the child's own work without the session around it (no pipe, no wake-ups, no
SCHED_IDLE preemption; the real session's child costs more: bench/bench_cpu_per_sample.py). Printed: CPU us per
limb-sample (min over runs) and per CAN frame. Process CPU time, not wall time: on a shared host it still inflates
with load (cache).
`--compare PYTHON`: an A/B against another checkout's interpreter (e.g. /work/wt-base/.venv/bin/python): the same
stream, applied by that checkout's `child_main`, runs alternating with this one's (A B A B ...).
"""
from __future__ import annotations

import argparse
import io
import json
import os
import pickle
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.benchlib import bench_args, emit, record
from sea_hil.config.loader import config_to_toml, load_config
from sea_hil.protocol import payloads
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import (
    T_US_MODULUS,
    DriverState,
    ErrorFlags,
    FeedbackAngle,
    FeedbackJoint1,
    FeedbackJoint2,
    Heartbeat,
    VoltageCmd,
)
from sea_hil.protocol.payloads import EventStatePayload, SetpointPayload, TriggerReason
from sea_hil.recorder import process
from sea_hil.recorder.process import ATTACHMENT, CANS, CLOSE, RECORD, child_main
from sea_hil.recorder.zenoh_tap import ZenohTap

WAKE_SAMPLES = 10        # samples per tap wake-up (tap_batch_s = 10 ms at 1 kHz)
BATCH_OPS = 512          # RecorderProcess.batch_ops
T0_NS = 1_700_000_000 * 10**9
_LEN = struct.Struct("<I")


def _zenoh_messages(k: int, t_ns: int) -> list[tuple[str, bytes, int]]:
    """The Zenoh messages (key, payload, receive time) the recorder takes around sample `k` of limb 1: a tracking
    record every 10 samples, a trigger event (its state, its tracking record, the setpoint) every 36."""
    x = (k % 1000) / 1000
    out: list[tuple[str, bytes, int]] = []
    if k % 10 == 0:
        out.append(("sea/limb1/event", json.dumps(
            {"t_s": k * 1e-3, "state_seq": k, "theta1_rad": 0.3 * x, "theta2_rad": -0.2 * x,
             "theta1_d_rad": 0.3 * x + 1e-3, "theta2_d_rad": -0.2 * x, "e1_rad": 1e-3, "e2_rad": 0.0}).encode(), t_ns))
    if k % 36 == 0:
        ev = k // 36
        reason = list(TriggerReason)[-1]
        out += [("sea/limb1/state", payloads.encode(EventStatePayload(
                    k, t_ns, k * 10**6, (0.3 * x, -0.2 * x), (x, -x), (1e-4 * x, -1e-4 * x), (1e-3 * x, 0.0),
                    event_seq=ev, reason=reason, trajectory_id=3298795889)), t_ns),
                ("sea/limb1/event", json.dumps(
                    {"t_s": k * 1e-3, "state_seq": k, "theta1_rad": 0.3 * x, "theta2_rad": -0.2 * x,
                     "theta1_d_rad": 0.3 * x, "theta2_d_rad": -0.2 * x, "event": True, "reason": reason.name,
                     "setpoint_seq": ev}).encode(), t_ns + 1000),
                ("sea/limb1/setpoint", payloads.encode(SetpointPayload(
                    ev + 1, t_ns, k, (1e-4 * x, -1e-4 * x), (1e-5, -1e-5), reason)), t_ns + 300_000)]
    return out


def _zenoh_ops(messages: list[tuple[str, bytes, int]], tap: ZenohTap) -> list[tuple[Any, ...]]:
    """What the session's Zenoh tap submits for `messages`: each as it came (`ZENOH`, decoded by the child) where
    this checkout's recorder process takes them so, else the records the tap makes of them (`RECORD`)."""
    zenoh_op = getattr(process, "ZENOH", None)
    if zenoh_op is not None:
        return [(zenoh_op, key, data, t) for key, data, t in messages]
    return [(RECORD, *r) for key, data, t in messages for r in tap.records(key, data, t)]


def stream(samples: int, limbs: int = 1) -> tuple[bytes, int]:
    """(the child's input, CAN frames in it) for `samples` samples of `limbs` limbs (module docstring)."""
    codec = SeaCodec(fd=None)
    cfg = load_config()
    ops: list[tuple[Any, ...]] = [(ATTACHMENT, "config.toml", config_to_toml(cfg).encode(), "text/plain", 0)]
    n_frames, ztap = 0, ZenohTap()
    for w in range(0, samples, WAKE_SAMPLES):
        frames: list[tuple[Any, ...]] = []
        zenoh: list[tuple[Any, ...]] = []
        for k in range(w, min(w + WAKE_SAMPLES, samples)):
            x, t_ns, q = (k % 1000) / 1000, T0_NS + k * 10**6, k % 256
            for node in range(1, limbs + 1):
                objs: list[Any] = [FeedbackAngle(node, q, 1000 * k % T_US_MODULUS, (0.3 * x, -0.2 * x)),
                                   FeedbackJoint1(node, q, 0.5 - x, 1e-3 * x, -1e-3 * x),
                                   FeedbackJoint2(node, q, x - 0.5, -1e-3 * x, 1e-3 * x),
                                   VoltageCmd(node, (20 * x - 10, 10 - 20 * x), q)]
                if k % 100 == 0:
                    objs.append(Heartbeat(node, DriverState.RUNNING, ErrorFlags(0), 0, 0, (k // 100) % 256))
                for i, obj in enumerate(objs):
                    m = codec.encode(obj)
                    frames.append((t_ns + 1000 * i, m.arbitration_id, m.dlc, bytes(m.data), False, False, False,
                                   False))
            zenoh += _zenoh_ops(_zenoh_messages(k, t_ns + 500_000), ztap)
        ops += [(CANS, frames), *zenoh]
        n_frames += len(frames)
    ops.append((CLOSE, {}))
    out, pending, n = io.BytesIO(), [], 0
    for op in ops:
        pending.append(op)
        n += len(op[1]) if op[0] == CANS else 1
        if n >= BATCH_OPS or op[0] == CLOSE:
            blob = pickle.dumps(pending, protocol=pickle.HIGHEST_PROTOCOL)
            out.write(_LEN.pack(len(blob)) + blob)
            pending, n = [], 0
    return out.getvalue(), n_frames


def one_run(data: bytes) -> float:
    """CPU s of `child_main` applying `data` into a temporary recording."""
    cfg = load_config().record
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.process_time()
        child_main(str(Path(tmp) / "b.mcap"), cfg.model_dump_json(), io.BytesIO(data))
        return time.process_time() - t0


def _other_run(python: str, samples: int, limbs: int) -> float:
    """One run under another checkout's interpreter: this bench package from a directory holding only it, so that
    `sea_hil` is the other checkout's."""
    with tempfile.TemporaryDirectory() as tmp:
        os.symlink(Path(__file__).resolve().parent, Path(tmp) / "bench")
        out = subprocess.run([python, "-m", "bench.bench_recorder_child", "--one-run", "--samples", str(samples),
                              "--limbs", str(limbs)], cwd=tmp, capture_output=True, text=True, check=True,
                             env={**os.environ, "PYTHONPATH": tmp})
    return float(out.stdout.split()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=3)
    ap.add_argument("--samples", type=int, default=5000)
    ap.add_argument("--limbs", type=int, default=1)
    ap.add_argument("--compare", default=None, help="A/B: another checkout's python (A)")
    ap.add_argument("--one-run", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.quick:
        args.runs, args.samples = 1, 500
    data, n_frames = stream(args.samples, args.limbs)
    if args.one_run:   # (--compare's child) CPU s of one run, after a warm-up
        one_run(stream(200, args.limbs)[0])
        print(one_run(data))
        return 0
    one_run(stream(200, args.limbs)[0])   # warm-up (imports, first chunk)
    limb_samples = args.samples * args.limbs
    rows: list[tuple[str, list[float]]] = []
    a: list[float] = []
    b: list[float] = []
    for _ in range(args.runs):
        if args.compare:
            a.append(_other_run(args.compare, args.samples, args.limbs))
        b.append(one_run(data))
    if args.compare:
        rows.append((f"A ({args.compare})", a))
    rows.append(("B (this checkout)" if args.compare else "this checkout", b))
    load = os.getloadavg()[0]
    print(f"{args.samples} samples x {args.limbs} limb(s) = {n_frames} frames, {args.runs} run(s), load average "
          f"{load:.1f}:")
    for label, cpu in rows:
        per = [1e6 * c / limb_samples for c in cpu]
        print(f"  {label}: CPU us per limb-sample {min(per):.1f}-{max(per):.1f}, per frame "
              f"{1e6 * min(cpu) / n_frames:.2f}-{1e6 * max(cpu) / n_frames:.2f}")
    if args.json:
        per_run = [1e6 * c / limb_samples for c in b]
        emit([record("7c", "recorder child: CPU per limb-sample (decode, encode, MCAP write)", runs=args.runs,
                     unit="us/limb-sample", per_run=per_run, p99=float("nan"), goal="(informative)",
                     metric="process CPU time of `child_main` over a real-time session's stream of operations "
                            f"({args.limbs} limb(s)), per limb-sample",
                     notes=f"load average {load:.1f}")], args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

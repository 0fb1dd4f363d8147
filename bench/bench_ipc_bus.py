"""The `ipc` CAN bus between two processes (protocol/ipc_bus.py): throughput, per-frame latency, frames lost.

Run: python -m bench.bench_ipc_bus [--runs 3] [--frames 50000] [--pings 5000] [--stall-s 0.5] [--udp GROUP]
                                   [--json OUT] [--quick]
Per run, in a fresh channel directory:
  throughput  a child process (this script with `--blast`) sends `--frames` classic 8-byte frames as fast as the bus
              takes them; this process reads them: frames/s from the first frame's arrival to the last's, the
              frames lost (never received: gaps in the index, and the tail) and `disordered` (received behind a
              newer one) -- 0 and 0 are the design's claim;
  latency     a child (`--echo`) answers each frame with one; one way = round trip / 2 on this process's monotonic
              clock, `--pings` round trips, one at a time;
  stall       the throughput run with a reader that stops for `--stall-s` after its first frame (a descheduled or
              paused process): on `ipc` the sender waits (`sender_waits`), nothing is lost; with `--udp GROUP` the
              same run on `udp_multicast:GROUP` too (needs a multicast route: run it under `unshare --net` with
              `ip link set lo up && ip route add 224.0.0.0/4 dev lo`), which drops what its receive buffer cannot hold.
The figures depend on the host's load: the record carries the 1-minute load average (benchlib.host_facts).
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from typing import Any

import can

from bench.benchlib import REPO, bench_args, emit, pct, record, stop_process, wait_ready
from sea_hil.errors import SeaHilError
from sea_hil.protocol.canbus import open_bus
from sea_hil.protocol.ipc_bus import IpcBus

CHANNEL = "bench"
PING_ID, PONG_ID, BLAST_ID = 0x10, 0x11, 0x20


def _frame(arbitration_id: int, i: int) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, data=i.to_bytes(8, "little"), is_extended_id=False)


def _open(spec: str, directory: str) -> can.BusABC:
    return IpcBus(CHANNEL, directory=directory) if spec == "ipc" else open_bus(spec)


def blast(spec: str, directory: str, n: int) -> None:
    """Child: join, say ready, wait for the go line, send `n` frames; print the bus's counters."""
    bus = _open(spec, directory)
    print("ready", flush=True)
    sys.stdin.readline()
    for i in range(n):
        bus.send(_frame(BLAST_ID, i))
    print(json.dumps({"dropped": getattr(bus, "frames_dropped", None), "waits": getattr(bus, "send_waits", None)}),
          flush=True)
    sys.stdin.readline()   # stay a member until the reader has everything (then leave)
    bus.shutdown()


def echo(directory: str) -> None:
    """Child: answer every ping with a pong carrying the same data, until stdin closes."""
    bus = IpcBus(CHANNEL, directory=directory)
    print("ready", flush=True)
    while True:
        msg = bus.recv(timeout=1.0)
        if msg is None:
            if sys.stdin.closed:
                break
            continue
        if msg.arbitration_id == PING_ID:
            if msg.data == b"\xff" * 8:
                break
            bus.send(_frame(PONG_ID, int.from_bytes(msg.data, "little")))
    bus.shutdown()


def _child(*args: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "bench.bench_ipc_bus", *args], cwd=REPO, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE)


def throughput_run(n: int, spec: str = "ipc", stall_s: float = 0.0) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="bench-ipc-") as d:
        rx = _open(spec, d)
        child = _child("--blast", spec, d, str(n))
        try:
            wait_ready(child)
            assert child.stdin is not None and child.stdout is not None
            child.stdin.write(b"go\n")
            child.stdin.flush()
            got, expect, missing, disordered, t_first, t_last = 0, 0, 0, 0, 0.0, 0.0
            while got < n:
                msg = rx.recv(timeout=10.0)
                if msg is None:
                    break
                t_last = time.perf_counter()
                if got == 0:
                    t_first = t_last
                    if stall_s > 0:
                        time.sleep(stall_s)   # the stalled reader this run is about (not a synchronisation)
                i = int.from_bytes(msg.data, "little")
                if i >= expect:            # a forward jump: the frames in between never arrived
                    missing, expect = missing + i - expect, i + 1
                else:                      # a frame behind the newest one: reordered or duplicated
                    disordered += 1
                got += 1
            report = json.loads(child.stdout.readline())
            child.stdin.write(b"done\n")
            child.stdin.flush()
        finally:
            stop_process(child)
            rx.shutdown()
    return {"bus": spec, "stall_s": stall_s,
            "frames_per_s": (got - 1) / (t_last - t_first) if got > 1 and t_last > t_first else 0.0,
            "lost": missing + n - expect, "disordered": disordered, "received": got, "dropped_by_sender": report["dropped"],
            "sender_waits": report["waits"]}


def latency_run(pings: int) -> list[float]:
    with tempfile.TemporaryDirectory(prefix="bench-ipc-") as d:
        bus = IpcBus(CHANNEL, directory=d)
        child = _child("--echo", d)
        one_way_us: list[float] = []
        try:
            wait_ready(child)
            for i in range(pings):
                t0 = time.perf_counter_ns()
                bus.send(_frame(PING_ID, i))
                while True:
                    msg = bus.recv(timeout=10.0)
                    if msg is None:
                        raise SeaHilError(f"no answer to ping {i}")
                    if msg.arbitration_id == PONG_ID and int.from_bytes(msg.data, "little") == i:
                        break
                one_way_us.append((time.perf_counter_ns() - t0) / 2e3)
            bus.send(can.Message(arbitration_id=PING_ID, data=b"\xff" * 8, is_extended_id=False))
        finally:
            stop_process(child)
            bus.shutdown()
    return one_way_us


def main() -> int:
    if sys.argv[1:2] == ["--blast"]:
        blast(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return 0
    if sys.argv[1:2] == ["--echo"]:
        echo(sys.argv[2])
        return 0
    ap = bench_args(__doc__.splitlines()[0], runs=3)
    ap.add_argument("--frames", type=int, default=50_000, help="frames per throughput run (default 50000)")
    ap.add_argument("--pings", type=int, default=5_000, help="round trips per latency run (default 5000)")
    ap.add_argument("--stall-s", type=float, default=0.5, help="the stalled reader's pause (default 0.5 s, below the bus's 1 s send timeout; 0: no run)")
    ap.add_argument("--udp", metavar="GROUP", help="also the stall run on udp_multicast:GROUP (a multicast route)")
    args = ap.parse_args()
    frames, pings, stall_s = (2_000, 200, 0.1) if args.quick else (args.frames, args.pings, args.stall_s)
    thr = [throughput_run(frames) for _ in range(args.runs)]
    lat = [latency_run(pings) for _ in range(args.runs)]
    buses = ["ipc", *([f"udp_multicast:{args.udp}"] if args.udp else [])]
    stalled = [throughput_run(frames, bus, stall_s) for bus in buses for _ in range(args.runs)] if stall_s > 0 else []
    all_us = [v for run in lat for v in run]
    lost = sum(int(r["lost"]) + int(r["disordered"]) for r in thr)
    records = [
        record("ipc-t", "ipc CAN bus throughput, two processes", runs=args.runs, metric="frames/s", unit="frames/s",
               per_run=[r["frames_per_s"] for r in thr], p99=min(r["frames_per_s"] for r in thr),
               p99_unit="frames/s (slowest run)", goal="0 frames lost", goal_met=lost == 0,
               notes=f"{frames} frames a run; lost or disordered {lost} in all runs; sender waits (full queue) "
                     f"{[r['sender_waits'] for r in thr]}", details=thr),
        record("ipc-l", "ipc CAN bus one-way latency, two processes (round trip / 2)", runs=args.runs,
               metric="p50 one-way latency", unit="us", per_run=[pct(run, 50) for run in lat], p99=pct(all_us, 99),
               notes=f"{pings} round trips a run, max {max(all_us):.0f} us"),
    ]
    ipc_stall_lost = sum(int(r["lost"]) + int(r["disordered"]) for r in stalled if r["bus"] == "ipc")
    if stalled:
        records.append(record(
            "ipc-s", f"frames lost with a reader stalled {stall_s:g} s, two processes", runs=args.runs,
            metric="frames lost (ipc)", unit="frames", per_run=[r["lost"] for r in stalled if r["bus"] == "ipc"],
            p99=max(r["lost"] for r in stalled), p99_unit="frames (most lost, any bus)", goal="0 frames lost on ipc",
            goal_met=ipc_stall_lost == 0,
            notes="; ".join(f"{b}: lost {[r['lost'] for r in stalled if r['bus'] == b]}, disordered "
                            f"{[r['disordered'] for r in stalled if r['bus'] == b]}, sender waits "
                            f"{[r['sender_waits'] for r in stalled if r['bus'] == b]}" for b in buses),
            details=stalled))
    emit(records, args.json)
    return 0 if lost == 0 and ipc_stall_lost == 0 else 1


if __name__ == "__main__":
    sys.exit(main())

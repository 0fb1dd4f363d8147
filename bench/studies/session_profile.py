"""Where the CPU of a real-time `sea-hil run --limbs N` session goes, per limb-sample (issue 17, batched nodes).

Run: python -m bench.studies.session_profile [--limbs 4] [--cycles 1] [--out DIR] [--json OUT] [-- EXTRA sea-hil run ARGS]
Runs the session as a child and samples its process tree with psutil every 0.2 s (the last CPU times seen of every
process and of every thread of the session process); a `py-spy dump` every 3 s names the session process's Python
threads (driver node `plant*`, edge mux / edges `edge*`, recorder tap, main thread). Threads
py-spy does not name (Zenoh's Rust runtime, numba, the C side of python-can) are grouped by their OS thread name.
Printed: CPU seconds and CPU us per limb-sample for the driver, the edges, the rest of the session process (Zenoh,
recorder taps, main loop), the controller children (one per limb) and the recorder child, plus the summary's
driver tick misses, edge loop p99 and closed-loop latency. CPU time is less load-sensitive than the real-time
figures, which on a loaded machine are not final (the load average is printed).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import psutil

from bench.cpu_window import thread_names


def _role(cmdline: list[str]) -> str:
    text = " ".join(cmdline)
    if "sea_hil.recorder" in text:
        return "recorder child"
    if " controller" in text or "controller_" in text:
        return "controllers"
    return "other child: " + " ".join(cmdline[:3])[:60]


def _thread_group(name: str) -> str:
    low = name.lower()
    if low.startswith(("plant", "driver")):
        return "driver (plant node)"
    if low.startswith("edge"):
        return "edges (edge mux / cores)"
    return f"session process: {name}"


class TreeSampler:
    """The last CPU times seen of every process of the tree under `root` and of every thread of `root`."""

    def __init__(self, root: psutil.Process) -> None:
        self.root = root
        self.procs: dict[int, tuple[str, float]] = {}
        self.threads: dict[int, float] = {}
        self.names: dict[int, str] = {}
        self.stop = threading.Event()

    def sample(self) -> None:
        try:
            self.threads.update({t.id: t.user_time + t.system_time for t in self.root.threads()})
            kids = self.root.children(recursive=True)
        except psutil.Error:
            return
        for p in kids:
            try:
                c = p.cpu_times()
                self.procs[p.pid] = (_role(p.cmdline()), c.user + c.system)
            except psutil.Error:
                continue

    def run(self) -> None:
        k = 0
        while not self.stop.wait(0.2):
            self.sample()
            k += 1
            if k % 15 == 0:   # every 3 s: name the threads alive now (py-spy), so short-lived ones are named too
                self.names.update(thread_names(self.root.pid)[0])


def profile(limbs: int, cycles: int, out: Path, extra: list[str]) -> dict[str, Any]:
    cmd = [str(Path(sys.executable).with_name("sea-hil")), "run", "--limbs", str(limbs), "--cycles", str(cycles),
           "--out", str(out), "--quiet", *extra]
    load = os.getloadavg()[0]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL)
    root = psutil.Process(proc.pid)
    sampler = TreeSampler(root)
    th = threading.Thread(target=sampler.run, daemon=True)
    th.start()
    try:
        rc = proc.wait(timeout=900)
    finally:
        sampler.stop.set()
        th.join()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    wall = time.monotonic() - t0
    summary = json.loads((out / "summary.json").read_text())
    groups: dict[str, float] = defaultdict(float)
    for tid, cpu in sampler.threads.items():
        groups[_thread_group(sampler.names.get(tid, "(unnamed, exited)"))] += cpu
    for role, cpu in sampler.procs.values():
        groups[role] += cpu
    ticks = summary["timing"]["driver"]["ticks"]
    buses = summary.get("limbs_total", {}).get("buses", 1)
    samples = max(1, ticks * limbs // buses)   # `ticks` sums the buses' drivers; each serves limbs / buses limbs
    return {"limbs": limbs, "rc": rc, "wall_s": wall, "load_avg_start": load, "limb_samples": samples,
            "cpu_s": dict(groups), "summary": summary}


def report(r: dict[str, Any]) -> None:
    s = r["summary"]
    drv = s["timing"]["driver"]
    total = sum(r["cpu_s"].values())
    print(f"sea-hil run --limbs {r['limbs']}: rc {r['rc']}, wall {r['wall_s']:.1f} s, load average at start "
          f"{r['load_avg_start']:.1f} (real-time figures loaded unless ~0), {r['limb_samples']} limb-samples")
    edge, lat = s["timing"].get("edge", {}), s["timing"].get("latency_us", {})
    limb_p99 = [round(e.get("timing", {}).get("latency_us", {}).get("p99", -1)) for e in s.get("limbs", [])]
    print(f"  driver tick misses {drv.get('tick_misses')} of {drv.get('ticks')}; edge loop p50/p99 "
          f"{edge.get('loop_us_p50', -1):.0f}/{edge.get('loop_us_p99', -1):.0f} us (first limb); closed loop p50/p99 "
          f"{lat.get('p50', -1):.0f}/{lat.get('p99', -1):.0f} us; per limb p99 {limb_p99} us")
    for name, cpu in sorted(r["cpu_s"].items(), key=lambda kv: -kv[1]):
        print(f"  {name:48s} {cpu:7.2f} s CPU  {1e6 * cpu / r['limb_samples']:7.1f} us/limb-sample")
    print(f"  {'total':48s} {total:7.2f} s CPU  {1e6 * total / r['limb_samples']:7.1f} us/limb-sample "
          f"({100 * total / r['wall_s']:.0f} % of one core)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limbs", type=int, default=4)
    ap.add_argument("--cycles", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="session output directory (default: a temporary one)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("extra", nargs="*", help="more `sea-hil run` arguments (after --)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="sea-hil-profile-") as tmp:
        r = profile(args.limbs, args.cycles, args.out or Path(tmp) / "run", args.extra)
    report(r)
    if args.json:
        args.json.write_text(json.dumps({k: v for k, v in r.items() if k != "summary"}, indent=1))
    return 0 if r["rc"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())

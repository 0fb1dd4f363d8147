"""Run every benchmark (the figures of BENCHMARKS.md) and regenerate BENCHMARKS.md from their JSON results.

Run: python -m bench.run_all [--quick] [--only NAME,...] [--render-only] [--results DIR] [--out BENCHMARKS.md]
Each script runs as a child process with `--json DIR/<name>.json`; its output is streamed with a progress prefix.
A failing script becomes a FAILED row, the others still run. The full run takes about 8 minutes on the 2-core
development machine; `--quick` (every script in its smoke mode) about 1-2 minutes, marked PRELIMINARY.
bench_simulate.py (figure 1) and bench_lockstep.py are other engineers' scripts: they are used with `--json` if
they accept it, otherwise their printed output is parsed.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from bench.benchlib import REPO, now_iso, record
from bench.report_md import render
from sea_hil.errors import SeaHilError

BENCH = Path(__file__).resolve().parent
# name, figure, full arguments, quick arguments, rough full-mode seconds
STEPS: list[tuple[str, str, list[str], list[str], int]] = [
    ("bench_simulate", "1", ["--runs", "5"], ["--quick"], 15),
    ("bench_lockstep", "1b", ["--runs", "3"], ["--runs", "1", "--controllers", "et"], 70),
    ("bench_zenoh_hop", "2", ["--runs", "5", "--pings", "2000"], ["--quick"], 25),
    ("bench_closed_loop_latency", "3", ["--runs", "5"], ["--quick"], 75),
    ("bench_driver_timing", "4", ["--duration", "60", "--edge", "--load"], ["--quick", "--edge", "--load"], 135),
    ("bench_timer_floor", "4f", ["--runs", "5", "--duration", "20"], ["--quick"], 105),   # the host's floor
    ("bench_session_timing", "4s", ["--runs", "3", "--limbs", "1,2,4", "--loaded"], ["--quick"], 480),   # tick misses and latency beside each run's floor, idle and loaded
    ("bench_bandwidth", "5", ["--runs", "3"], ["--quick"], 55),
    ("bench_scale", "6", ["--duration", "10"], ["--quick"], 130),   # 5 counts x 2 layouts x 11 s
    ("bench_cpu_per_sample", "6c", ["--limbs", "1,2,4", "--runs", "3"], ["--quick"], 900),   # 9 sessions
    ("bench_mcap", "7", ["--runs", "3"], ["--quick"], 30),
    ("bench_recorder_child", "7c", ["--runs", "3"], ["--quick"], 30),
    ("bench_live", "8", ["--runs", "3"], ["--quick"], 150),
    ("bench_sweep", "9", ["--runs", "1"], ["--quick"], 60),
    ("bench_ros2_export", "ros2", ["--runs", "3"], ["--quick"], 60),   # a lockstep session, then 3 exports
    ("bench_ipc_bus", "ipc", ["--runs", "3"], ["--quick"], 60),   # the ipc CAN bus between two processes
]
# opt-in (`--long`): the endurance figures take many minutes of one real-time session each
LONG_STEPS: list[tuple[str, str, list[str], list[str], int]] = [
    ("bench_soak", "10", ["--minutes", "10"], ["--quick"], 4800),
]


def _accepts_json(module: str) -> bool:
    out = subprocess.run([sys.executable, "-m", module, "--help"], cwd=REPO, capture_output=True, text=True,
                         timeout=60)
    return "--json" in out.stdout


def _stream(cmd: list[str], prefix: str, timeout_s: float) -> tuple[int, str]:
    """Run `cmd`, echo each output line with `prefix`, return (exit status, full output)."""
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    deadline = time.monotonic() + timeout_s
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            print(f"{prefix} {line.rstrip()}", flush=True)
            if time.monotonic() > deadline:
                raise TimeoutError(f"{cmd[1]} took longer than {timeout_s:.0f} s")
        proc.wait(timeout=max(deadline - time.monotonic(), 1.0))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, "".join(lines)


def parse_simulate(text: str, cmd: str, runs: int) -> list[dict[str, Any]]:
    """Figure 1 from bench_simulate's printed 'CPU s per run: median X  min Y  max Z'."""
    m = re.search(r"CPU s per run: median ([\d.]+)\s+min ([\d.]+)\s+max ([\d.]+)", text)
    if m is None:
        raise ValueError("no 'CPU s per run' line in bench_simulate output")
    med, lo, hi = (float(x) for x in m.groups())
    rec = record("1", "offline closed-loop simulation speed (one walking cycle)", runs=runs,
                 metric="CPU s per simulated walking cycle (time.process_time), median/min/max over runs",
                 unit="CPU s/cycle", per_run=[lo, hi], median=med, p99=float("nan"), goal="(informative)",
                 command=cmd, notes=" ".join(ln.strip() for ln in text.splitlines() if ln.strip()))
    return [rec]


def parse_lockstep(text: str, cmd: str, runs: int) -> list[dict[str, Any]]:
    """Rows from bench_lockstep's printed JSON: per controller, session wall s per walking cycle."""
    data = json.loads(text[text.index("{"):text.rindex("}") + 1])
    out = []
    for i, (ctl, v) in enumerate((k, v) for k, v in data.items() if isinstance(v, dict)):
        st = v["session_wall_s_per_cycle"]
        out.append(record(f"1{chr(ord('b') + i)}", f"lockstep session wall time per cycle, {ctl}",
                          runs=data.get("runs", runs), metric="summary.json timing.wall_s per walking cycle "
                          f"(process wall incl. start-up: median {v['process_wall_s_per_cycle']['median']} s)",
                          unit="s/cycle", per_run=[st["min"], st["max"]], median=st["median"], p99=float("nan"),
                          goal="(informative)", command=cmd))
    return out


def run_step(name: str, args: list[str], results: Path, timeout_s: float) -> list[dict[str, Any]]:
    module = f"bench.{name}"
    cmd_s = " ".join(["python", "-m", module, *args])
    if not (BENCH / f"{name}.py").exists():
        return []
    out_json = results / f"{name}.json"
    use_json = _accepts_json(module)
    cmd = [sys.executable, "-m", module, *args, *(["--json", str(out_json)] if use_json else [])]
    status, text = _stream(cmd, f"[{name}]", timeout_s)
    if status != 0:
        raise SeaHilError(f"exit status {status}: {text.strip().splitlines()[-1] if text.strip() else ''}")
    if use_json:
        return json.loads(out_json.read_text(encoding="utf-8"))
    runs = int(args[args.index("--runs") + 1]) if "--runs" in args else 1
    recs = parse_simulate(text, cmd_s, runs) if name == "bench_simulate" else parse_lockstep(text, cmd_s, runs)
    out_json.write_text(json.dumps(recs, indent=2) + "\n", encoding="utf-8")
    return recs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke run: every script in its quickest mode")
    ap.add_argument("--only", help="comma-separated script names (e.g. bench_mcap,bench_scale)")
    ap.add_argument("--long", action="store_true",
                    help="also run the long endurance benchmarks (bench_soak: a 10 min session); their last results "
                         "stay in the markdown either way")
    ap.add_argument("--render-only", action="store_true", help="only rewrite the markdown from existing JSON")
    ap.add_argument("--results", type=Path, default=BENCH / "results", help="JSON directory (default bench/results)")
    ap.add_argument("--out", type=Path, default=REPO / "BENCHMARKS.md", help="markdown file to write")
    args = ap.parse_args(argv)
    args.results.mkdir(parents=True, exist_ok=True)
    only = set(args.only.split(",")) if args.only else None
    steps = [s for s in STEPS + LONG_STEPS if (only is None and (s in STEPS or args.long)) or
             (only is not None and s[0] in only)]
    t0 = time.monotonic()
    for i, (name, fig, full, quick, est_s) in enumerate(steps):
        if args.render_only:
            break
        chosen = quick if args.quick else full
        print(f"=== [{i + 1}/{len(steps)}] {name} {' '.join(chosen)} (full mode ~{est_s} s; "
              f"{time.monotonic() - t0:.0f} s elapsed)", flush=True)
        try:
            run_step(name, chosen, args.results, timeout_s=max(10 * est_s, 300))
        except Exception as err:  # noqa: BLE001 - one failing benchmark must not stop the others
            fail = {"figure": fig, "title": name, "command": f"python -m bench.{name} {' '.join(chosen)}",
                    "error": str(err)[:300], "date": now_iso()}
            (args.results / f"{name}.json").write_text(json.dumps([fail]) + "\n", encoding="utf-8")
            print(f"=== {name} FAILED: {err}", flush=True)
    records: list[dict[str, Any]] = []
    for name, *_ in STEPS + LONG_STEPS:
        path = args.results / f"{name}.json"
        if path.exists():
            records += json.loads(path.read_text(encoding="utf-8"))
    records.sort(key=lambda r: str(r["figure"]))
    total_s = time.monotonic() - t0
    header = f"Generated {now_iso()} by `python -m bench.run_all{' --quick' if args.quick else ''}`."
    args.out.write_text(render(records, preliminary=args.quick, total_s=total_s, header=header), encoding="utf-8")
    print(f"=== wrote {args.out} ({len(records)} rows) in {total_s:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

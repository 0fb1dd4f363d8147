"""CPU cost of the offline closed loop: `closed_loop.simulate(cfg, mode)` for one walking cycle, N runs (figure 1).

Run: python -m bench.bench_simulate [--runs 5] [--mode et] [--config FILE] [--no-jit] [--cold] [--json OUT]
Prints the warm-up (first call: numba import + JIT compile or load from numba's disk cache) separately, then the
median/min/max CPU seconds (time.process_time) of the timed runs and simulated seconds per CPU second.
--cold points numba's cache at an empty temporary directory, so the warm-up includes a full compile.
--no-jit times the plain-Python reference path of the same kernel.
"""
from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time

from bench.benchlib import bench_args, emit, record
from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.jit import compiled
from sea_hil.offline.closed_loop import simulate
from sea_hil.offline.drive_kernel import make_session_steps

BASELINE_CPU_S = 0.32  # per 10 s cycle before the numba kernel (pure Python, issue 6)
GOAL_REALTIME_X = 200.0


def measure(cfg: SeaHilConfig, mode: str, runs: int, jit: bool) -> tuple[float, list[float], float]:
    """(warm-up CPU s of the first call, CPU s of each timed run, simulated seconds of one run)."""
    t0 = time.process_time()
    res = simulate(cfg, mode, cycles=1, jit=jit)
    warmup_s = time.process_time() - t0
    cpu_s: list[float] = []
    for _ in range(runs):
        t0 = time.process_time()
        simulate(cfg, mode, cycles=1, jit=jit)
        cpu_s.append(time.process_time() - t0)
    return warmup_s, cpu_s, res.duration_s


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=5)
    ap.add_argument("--mode", choices=("et", "tt"), default="et", help="controller mode (default et)")
    ap.add_argument("--config", metavar="FILE", help="TOML overlay on the default config")
    ap.add_argument("--no-jit", action="store_true", help="time the plain-Python path")
    ap.add_argument("--cold", action="store_true", help="empty numba cache: the warm-up includes the JIT compile")
    args = ap.parse_args(argv)
    if args.runs < 1:
        ap.error("--runs must be >= 1")
    runs = 1 if args.quick else args.runs
    cache_dir = tempfile.TemporaryDirectory(prefix="sea-hil-numba-") if args.cold else None
    if cache_dir is not None:
        os.environ["NUMBA_CACHE_DIR"] = cache_dir.name  # read when numba is first imported (inside the warm-up)
    cfg = load_config(args.config)
    warmup_s, cpu_s, duration_s = measure(cfg, args.mode, runs, jit=not args.no_jit)
    kernel = None if args.no_jit else compiled(make_session_steps)
    stats = kernel.stats if kernel is not None else None
    med = statistics.median(cpu_s)
    path = "numba kernel" if kernel is not None else "plain Python"
    print(f"closed_loop.simulate(cfg, {args.mode!r}) [{path}]: {duration_s:.1f} s simulated "
          f"(inner {cfg.can.feedback_rate_hz:.0f} Hz, {cfg.sim.substeps} RK4 sub-steps), {runs} runs")
    if stats is not None:
        print(f"warm-up (first call: numba import + {'compile' if sum(stats.cache_misses.values()) else 'cache load'})"
              f": {warmup_s:.3f} CPU s, of which beyond a steady run {warmup_s - med:.3f} s")
    print(f"CPU s per run: median {med:.4f}  min {min(cpu_s):.4f}  max {max(cpu_s):.4f}")
    print(f"simulated s per CPU s: {duration_s / med:.1f} (median run; goal >= {GOAL_REALTIME_X:.0f})")
    goal_cpu_s = duration_s / GOAL_REALTIME_X
    details = [{"path": path, "mode": args.mode, "simulated_s": duration_s, "warmup_cpu_s": warmup_s,
                "jit_cache_hits": sum(stats.cache_hits.values()) if stats else None,
                "jit_cache_misses": sum(stats.cache_misses.values()) if stats else None,
                "realtime_factor": duration_s / med}]
    rec = record("1", "offline closed loop: CPU s per 10 s walking cycle", runs=runs, metric="cpu_s_per_cycle",
                 unit="s", per_run=cpu_s, p99=max(cpu_s), baseline=BASELINE_CPU_S,
                 baseline_label="pure-Python loop before issue 6", goal=f"<= {goal_cpu_s:.3f} CPU s (>= 200x real time)",
                 goal_met=med <= goal_cpu_s, notes="p99 = max of runs; warm-up reported in details", details=details)
    if args.json is not None:
        emit([rec], args.json)
    if cache_dir is not None:
        cache_dir.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A 1,000-point offline sweep with delay, jitter and loss (figure 9): wall time of `sea-hil sweep --engine offline`.

Run: python -m bench.bench_sweep [--runs 1] [--jobs N] [--scheme default|paper] [--quick] [--json OUT]
The grid: eta 0.2,0.3,0.5,0.8,1.2 x r 0.05,0.1,0.2 (15 ET points + 1 TT reference per link condition) x delay
0,5,10,20 ms x jitter 0,1,2,5 ms x loss 0,0.01,0.02,0.05 = 64 link conditions, 1,024 points, one 10 s walking cycle
each (plus the 0.5 s lead-in), seed 1, on the embedded local Dask cluster (`--jobs` worker processes). The wall time
covers the whole command: interpreter start, cluster start, numba load in every worker, every point, the CSV and the
figure. `--scheme default` (the default: the trigger at the edge with the model lookahead and prediction, issue 16)
or `paper` (`--trigger controller --compensation none`). Before the first run the offline engine's kernels are
compiled into numba's disk cache (`warm-up`, reported apart: a one-time cost after an install or a source change,
which every later sweep skips). Per run it also reports
the mean point wall time inside the workers (the `wall_s` column) and the CPU time of the whole command (its process
and every worker process: user + system, less sensitive to a loaded machine than the wall time). `--quick`: 2 link
conditions (32 points), numbers not meaningful.
"""
from __future__ import annotations

import csv
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.benchlib import REPO, bench_args, emit, record

GOAL_S = 60.0
GRID = {"--eta": "0.2,0.3,0.5,0.8,1.2", "--r": "0.05,0.1,0.2", "--delay-ms": "0,5,10,20", "--jitter-ms": "0,1,2,5",
        "--loss": "0,0.01,0.02,0.05"}
QUICK = {**GRID, "--delay-ms": "0,10", "--jitter-ms": "1", "--loss": "0.02"}


SCHEMES = {"default": [], "paper": ["--trigger", "controller", "--compensation", "none"]}
WARM_UP = ("import logging; logging.disable(logging.CRITICAL); from sea_hil.config.loader import load_config; "
           "from sea_hil.offline.session_engine import run_engine; "
           "[run_engine(load_config(None, {'trajectory': {'period_s': 0.05, 'lead_in_s': 0.01}, **ov}), 'et') for ov in "
           "({}, {'trigger': {'placement': 'controller'}, 'controller': {'compensation': 'none'}})]")


def warm_up() -> float:
    """Seconds to compile (or load) the offline engine's kernels once, in a process of its own."""
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", WARM_UP], cwd=REPO, check=True, stdin=subprocess.DEVNULL, timeout=600)
    return time.monotonic() - t0


def _children_cpu_s() -> float:
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def run_once(grid: dict[str, str], jobs: int, out: Path, scheme: str = "default"
             ) -> tuple[float, int, int, float, float]:
    """(wall s, points, ok points, mean point wall s inside the workers, CPU s of the command and its workers) of
    one sweep command."""
    cmd = [sys.executable, "-m", "sea_hil.cli", "sweep", "--out", str(out), "--engine", "offline", "--seed", "1",
           "--jobs", str(jobs), *SCHEMES[scheme]]
    for k, v in grid.items():
        cmd += [k, v]
    cpu0, t0 = _children_cpu_s(), time.monotonic()
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=3600)
    wall_s, cpu_s = time.monotonic() - t0, _children_cpu_s() - cpu0
    if proc.returncode not in (0, 1):
        raise SystemExit(f"sweep failed ({proc.returncode}): {proc.stderr[-2000:]}")
    with (out / "sweep.csv").open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    point_s = sum(float(r["wall_s"]) for r in rows) / max(1, len(rows))
    return wall_s, len(rows), sum(r["status"] == "ok" for r in rows), point_s, cpu_s


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=1)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes (default: CPUs)")
    ap.add_argument("--scheme", choices=tuple(SCHEMES), default="default", help="control scheme (default: default)")
    args = ap.parse_args(argv)
    grid = QUICK if args.quick else GRID
    walls: list[float] = []
    warm_s = warm_up()
    print(f"warm-up (numba cache of the offline engine's kernels): {warm_s:.1f} s", flush=True)
    details = []
    for i in range(args.runs):
        with tempfile.TemporaryDirectory(prefix="sea-hil-bench-sweep-") as tmp:
            wall_s, n, ok, point_s, cpu_s = run_once(grid, args.jobs, Path(tmp) / "sw", args.scheme)
        walls.append(wall_s)
        details.append({"run": i + 1, "points": n, "ok": ok, "wall_s": wall_s, "points_per_s": n / wall_s,
                        "jobs": args.jobs, "scheme": args.scheme, "point_wall_ms": point_s * 1e3, "warm_up_s": warm_s, "cpu_s": cpu_s})
        print(f"run {i + 1}: {n} points ({ok} ok) in {wall_s:.1f} s wall, {n / wall_s:.1f} points/s, "
              f"{args.jobs} worker processes, {point_s * 1e3:.0f} ms per point in a worker, {cpu_s:.1f} s CPU "
              "(command + workers)", flush=True)
    worst = max(walls)
    rec = record("9", f"offline sweep of {details[0]['points']} points with delay, jitter and loss ({args.scheme} "
                 "scheme)", runs=args.runs,
                 metric="wall_s", unit="s", per_run=walls, p99=worst, goal=f"< {GOAL_S:.0f} s for 1,000 points",
                 goal_met=(not args.quick) and worst < GOAL_S,
                 notes="whole command: start-up, local Dask cluster, numba load per worker, all points, CSV, figure "
                       "(numba cache warmed first: warm_up_s)",
                 details=details)
    emit([rec], args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""CPU cost of the offline closed loop: `closed_loop.simulate(cfg, mode)` for one walking cycle, N runs.

Run: python bench/bench_simulate.py [--runs 5] [--mode et] [--config FILE]
Prints median/min/max CPU seconds (time.process_time) per run and simulated seconds per CPU second.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # runnable from a source checkout

from protocol.config import SeaHilConfig, load_config  # noqa: E402
from sea_hil.closed_loop import simulate  # noqa: E402


def measure(cfg: SeaHilConfig, mode: str, runs: int) -> tuple[list[float], float]:
    """CPU seconds of each run and the simulated duration of one run."""
    cpu_s: list[float] = []
    duration_s = 0.0
    for _ in range(runs):
        t0 = time.process_time()
        res = simulate(cfg, mode, cycles=1)
        cpu_s.append(time.process_time() - t0)
        duration_s = res.duration_s
    return cpu_s, duration_s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5, help="number of timed runs (default 5)")
    ap.add_argument("--mode", choices=("et", "tt"), default="et", help="controller mode (default et)")
    ap.add_argument("--config", metavar="FILE", help="TOML overlay on the default config")
    args = ap.parse_args(argv)
    if args.runs < 1:
        ap.error("--runs must be >= 1")
    cfg = load_config(args.config)
    cpu_s, duration_s = measure(cfg, args.mode, args.runs)
    med = statistics.median(cpu_s)
    print(f"closed_loop.simulate(cfg, {args.mode!r}): {duration_s:.1f} s simulated "
          f"(inner {cfg.controller.inner_rate_hz:.0f} Hz, {cfg.sim.substeps} RK4 sub-steps), {args.runs} runs")
    print(f"CPU s per run: median {med:.3f}  min {min(cpu_s):.3f}  max {max(cpu_s):.3f}")
    print(f"simulated s per CPU s: {duration_s / med:.1f} (median run)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

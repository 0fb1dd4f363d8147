"""Wall time of lockstep sessions: `sea-hil run --lockstep --controller {et,tt} --cycles N`, N runs each.

Run: python -m bench.bench_lockstep [--runs 3] [--controllers et,tt] [--cycles 1] [--config FILE]
Each run is a fresh `python -m sea_hil.cli run --lockstep --quiet` process. Prints one JSON object: per controller
the session wall time (`wall_s` of summary.json: start of the nodes to the closed MCAP), the whole process wall
time (start-up, summary and figures included), both per walking cycle, as median/min/max over the runs.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def one_run(controller: str, cycles: int, out: Path, config: str | None) -> tuple[float, float]:
    """(session wall_s, process wall s) of one lockstep run."""
    cmd = [sys.executable, "-m", "sea_hil.cli", "run", "--lockstep", "--quiet", "--controller", controller,
           "--cycles", str(cycles), "--out", str(out)] + (["--config", config] if config else [])
    t0 = time.monotonic_ns()
    subprocess.run(cmd, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, timeout=600)
    proc_s = (time.monotonic_ns() - t0) * 1e-9
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    return float(summary["timing"]["wall_s"]), proc_s


def _stats(values: list[float], cycles: int) -> dict[str, float]:
    per = [v / cycles for v in values]
    return {"median": round(statistics.median(per), 3), "min": round(min(per), 3), "max": round(max(per), 3)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="timed runs per controller (default 3)")
    ap.add_argument("--controllers", default="et,tt", help="comma-separated (default et,tt)")
    ap.add_argument("--cycles", type=int, default=1, help="walking cycles per run (default 1)")
    ap.add_argument("--config", metavar="FILE", help="TOML overlay on the default config")
    args = ap.parse_args(argv)
    if args.runs < 1 or args.cycles < 1:
        ap.error("--runs and --cycles must be >= 1")
    result: dict[str, Any] = {"runs": args.runs, "cycles": args.cycles}
    with tempfile.TemporaryDirectory(prefix="bench-lockstep-") as tmp:
        for ctl in args.controllers.split(","):
            walls, procs = [], []
            for i in range(args.runs):
                w, p = one_run(ctl, args.cycles, Path(tmp) / f"{ctl}{i}", args.config)
                walls.append(w)
                procs.append(p)
            result[ctl] = {"session_wall_s_per_cycle": _stats(walls, args.cycles),
                           "process_wall_s_per_cycle": _stats(procs, args.cycles),
                           "session_wall_s": [round(w, 3) for w in walls]}
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())

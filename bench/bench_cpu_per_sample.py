"""Steady-state CPU per limb-sample of a real-time `sea-hil run --limbs N`, per process and per thread (issue 17).

Run: python -m bench.bench_cpu_per_sample [--limbs 1,2,4] [--runs 3] [--warm 2] [--window 6] [--profile]
     [--compare OTHER_SEA_HIL] [--json OUT] [--end-after-window] [-- EXTRA sea-hil run ARGS]
`--compare PATH`: an A/B against another checkout's `sea-hil` executable (e.g. a worktree of the base commit with its
own venv): its runs (A) and this checkout's (B) alternate, A B A B ..., so both see the same load.
Each run starts `sea-hil run --limbs N --cycles 1` with its progress lines on and follows them (bench/cpu_window.py).
Start-up (imports, numba, Zenoh, the controllers' start-up) and the end (report, figures) are excluded: the CPU
times of every thread of the session process and of every child process (controllers, recorder) are read from /proc
`--warm` s of wall time after the first setpoint arrived (snapshot A) and `--window` s later (snapshot B). The
simulated time the progress lines report at A and B gives the limb-samples integrated in between (every executed
driver tick is one sample of each limb; a skipped deadline is no sample). Printed per thread group: CPU us per
limb-sample (min-max over the runs). CPU time is far less load-sensitive than the real-time figures, but a loaded
machine still inflates it somewhat (cache, migrations); the load average is printed.
`--end-after-window`: kill each session (its whole process tree) once its window is read instead of waiting for
its end: on a loaded machine its SCHED_IDLE recorder catches up for minutes; the tick counts are then not known.
`--floor-s S` (default 10; 0: none): before each run, the host's floor (the empty 1 kHz loop of
sea_hil.runtime.timer_floor at the driver's priority) for S s, printed and recorded beside the run's tick misses.
`--profile`: one more run per count, not in the table (py-spy's sampling inflates the target's CPU), with a
`py-spy record --nonblocking --gil` of the session process over its window, printing the top functions by own
samples per thread group (bench/studies/cpu_profile.py).
"""
from __future__ import annotations

import argparse
import io
import json
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from bench.benchlib import emit, record
from bench.cpu_window import WindowResult, measure
from sea_hil.config.loader import load_config
from sea_hil.runtime.timer_floor import measure_floor

FIGURES = "cdefgh"   # BENCHMARKS.md figures 6c, 6d, ... in the order of --limbs


def _span(values: list[float]) -> str:
    if not values:
        return "-"
    lo, hi = min(values), max(values)
    return f"{lo:7.1f}" if len(values) == 1 else f"{lo:7.1f}-{hi:<7.1f}"


def floored(floor_s: float, run: Callable[[], WindowResult]) -> tuple[float | None, WindowResult]:
    """(the host floor's miss % over `floor_s` s measured just before, None if 0 s; then `run()`'s result)."""
    floor = measure_floor(floor_s, load_config().timing.realtime_priority)["miss_pct"] if floor_s > 0 else None
    return floor, run()


def report(limbs: int, runs: list[WindowResult], label: str = "",
           floors: list[float | None] | None = None) -> dict[str, Any]:
    groups = sorted({g for r in runs for g in r.cpu_s}, key=lambda g: -max(r.per_sample_us(g) for r in runs))
    print(f"\n{label}--limbs {limbs}: {len(runs)} run(s), load average at start "
          f"{', '.join(f'{r.load_avg:.1f}' for r in runs)}; window {', '.join(f'{r.samples}' for r in runs)} "
          f"limb-samples; CPU us per limb-sample (min-max):")
    table: dict[str, list[float]] = {}
    for g in groups:
        table[g] = [r.per_sample_us(g) for r in runs]
        sys_pct = [100 * r.sys_s.get(g, 0.0) / r.cpu_s[g] for r in runs if r.cpu_s.get(g, 0.0) > 0]
        print(f"  {g:44s} {_span(table[g])}  (system {_span(sys_pct).strip()} %)")
    table["total"] = [r.total_us() for r in runs]
    sys_total = [100 * sum(r.sys_s.values()) / max(sum(r.cpu_s.values()), 1e-9) for r in runs]
    print(f"  {'total':44s} {_span(table['total'])}  (system {_span(sys_total).strip()} %)")
    misses = [f"{r.misses}/{r.ticks}" if r.ticks else "-" for r in runs]   # "-": session ended early, not known
    floor_s = ", ".join("-" if f is None else f"{f:.3f} %" for f in floors or [None] * len(runs))
    print(f"  (driver tick misses of the whole session: {', '.join(misses)}; host floor before each: {floor_s})")
    rec = [r.recorder_us() for r in runs]
    lost = [r.lost() for r in runs]
    print(f"  recorder (child + taps): {_span(rec).strip()} us per limb-sample; frames lost (recording vs sent, "
          f"whole session): {', '.join('-' if x is None else str(x) for x in lost)}")
    print(f"  recording complete (summary.json completeness, every limb): "
          f"{', '.join('-' if r.complete is None else 'yes' if r.complete else 'NO' for r in runs)}")
    whole = [r.child_session_us() for r in runs]
    if any(w is not None for w in whole):
        print(f"  recorder child over the whole session (its own CPU count): "
              f"{', '.join('-' if w is None else f'{w:.1f}' for w in whole)} us per limb-sample")
    for r in runs:
        if r.recorded:
            print(f"    recorded: {r.recorded}")
    return {"label": label, "limbs": limbs, "us_per_limb_sample": table, "samples": [r.samples for r in runs],
            "load_avg": [r.load_avg for r in runs], "misses": misses, "floor_pct": floors or [None] * len(runs), "recorder_us": rec, "lost": lost,
            "recorded": [r.recorded for r in runs], "child_session_us": whole}


def as_record(k: int, row: dict[str, Any], warm_s: float, window_s: float) -> dict[str, Any]:
    """The BENCHMARKS.md row of one limb count (figure 6c, 6d, ...): total CPU us per limb-sample per run."""
    groups = {g: v for g, v in row["us_per_limb_sample"].items() if g != "total" and max(v) >= 1.0}
    return record(f"6{FIGURES[k]}", f"steady-state CPU per limb-sample of `sea-hil run --limbs {row['limbs']}`",
                  runs=len(row["samples"]), unit="us/limb-sample", per_run=row["us_per_limb_sample"]["total"],
                  p99=float("nan"), goal="(informative; the lever behind tick misses)",
                  metric=f"CPU of every thread of the session and of its children over a {window_s:g} s window "
                         f"from {warm_s:g} s after the first setpoint, per limb-sample integrated in it",
                  details=[{"group": g, "min_us": min(v), "max_us": max(v)} for g, v in groups.items()],
                  notes=f"load average at the starts {row['load_avg']}; window limb-samples {row['samples']}; "
                        f"driver tick misses of each whole session {row['misses']} beside the host floor measured "
                        f"just before it {row['floor_pct']} %")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limbs", default="1,2,4")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--warm", type=float, default=2.0, help="wall s after the first setpoint before snapshot A")
    ap.add_argument("--window", type=float, default=6.0, help="wall s between snapshots A and B")
    ap.add_argument("--profile", action="store_true", help="one more run per count under py-spy record")
    ap.add_argument("--floor-s", type=float, default=10.0, help="host floor before each run, s (0: none)")
    ap.add_argument("--compare", default=None, help="A/B: another checkout's sea-hil executable (A)")
    ap.add_argument("--json", type=Path, default=None, help="BENCHMARKS.md records (benchlib) to this file")
    ap.add_argument("--quick", action="store_true", help="smoke mode: one 1-limb run, a 3 s window")
    ap.add_argument("--end-after-window", action="store_true",
                    help="kill each session right after its window (no waiting for its recorder on a loaded "
                         "machine; no tick counts then)")
    ap.add_argument("extra", nargs="*", help="more `sea-hil run` arguments (after --)")
    args = ap.parse_args(argv)
    if isinstance(sys.stdout, io.TextIOWrapper):
        sys.stdout.reconfigure(line_buffering=True)   # each table as soon as its count is done, also into a file
    if args.quick:
        args.limbs, args.runs, args.window, args.profile, args.floor_s = "1", 1, 3.0, False, 1.0
    out = []
    for n in (int(x) for x in args.limbs.split(",")):
        if args.compare:
            end = args.end_after_window
            pairs = [(floored(args.floor_s, partial(measure, n, args.warm, args.window, args.extra,
                                                    sea_hil=args.compare, end_after=end)),
                      floored(args.floor_s, partial(measure, n, args.warm, args.window, args.extra, end_after=end)))
                     for _ in range(args.runs)]
            out.append(report(n, [a[1] for a, _ in pairs], f"A ({args.compare}) ", [a[0] for a, _ in pairs]))
            out.append(report(n, [b[1] for _, b in pairs], "B (this checkout) ", [b[0] for _, b in pairs]))
        else:
            runs = [floored(args.floor_s, partial(measure, n, args.warm, args.window, args.extra,
                                                  end_after=args.end_after_window)) for _ in range(args.runs)]
            out.append(report(n, [r for _, r in runs], "", [f for f, _ in runs]))
        if args.profile:
            hot = measure(n, args.warm, args.window, args.extra, profile=True).hot
            print(f"  top own-GIL functions (py-spy, one more run):\n{hot}")
            out[-1]["hot"] = hot
    if args.json and not args.compare:
        emit([as_record(k, row, args.warm, args.window) for k, row in enumerate(out)], args.json)
    elif args.json:   # an A/B is not a BENCHMARKS.md row: both tables as they are
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

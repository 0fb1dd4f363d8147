"""Figure 4s: driver tick misses of the default real-time session (`sea-hil run --controller et --cycles 1`), and,
with `--levers`, the `[timing]` levers measured one by one in interleaved A/B pairs (docs/timing.md).

Run: python -m bench.bench_session_timing [--runs 3] [--levers LEVER,...] [--pairs 2] [--json OUT]
(levers: fifo, fifo-process, fifo-session; the busy-wait tail, GC in the slack, the switch interval and CPU pinning
were measured as no gain and removed, docs/timing.md)
A tick miss is a skipped driver deadline (a tick later than one whole period: summary.json `timing.driver`
`tick_misses` of `ticks`), not a merely late tick. Each session's CPU time (RUSAGE_CHILDREN: the run process, its
controller and recorder children) is divided by its driver ticks: CPU per tick. With `--levers`, every lever is
compared against the baseline with all levers off (`[timing]` of docs/timing.md), each pair run A then B, so load
drifts hit both alike; on a loaded machine only these paired differences mean something.
"""
from __future__ import annotations

import resource
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench.benchlib import bench_args, command_line, emit, pct, record, sea_hil_run, sea_hil_run_cmd

GOAL_MISS_PCT = 0.1
OFF = {"realtime_priority": 0, "realtime_scope": "driver"}
LEVERS: dict[str, dict[str, Any]] = {
    "fifo": {"realtime_priority": 50},
    "fifo-process": {"realtime_priority": 50, "realtime_scope": "process"},
    "fifo-session": {"realtime_priority": 50, "realtime_scope": "session"},
}


def _toml(timing: dict[str, Any]) -> str:
    vals = {k: str(v).lower() if isinstance(v, bool) else f'"{v}"' if isinstance(v, str) else str(v)
            for k, v in timing.items()}
    return "[timing]\n" + "".join(f"{k} = {v}\n" for k, v in vals.items())


def session(out: Path, timing: dict[str, Any] | None) -> dict[str, Any]:
    """One default session (with `timing` as its `[timing]` section, else the default config): its figures."""
    extra: tuple[str, ...] = ()
    if timing is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "timing.toml").write_text(_toml(timing), encoding="utf-8")
        extra = ("--config", str(out / "timing.toml"))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    s = sea_hil_run(out, controller="et", extra=extra)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    drv = s["timing"]["driver"]
    ticks, misses = int(drv["ticks"]), int(drv["tick_misses"])
    lat = s["timing"]["latency_us"]
    return {"ticks": ticks, "tick_misses": misses, "miss_pct": 100.0 * misses / ticks if ticks else float("nan"),
            "cpu_us_per_tick": 1e6 * cpu_s / ticks if ticks else float("nan"), "latency_p50_us": lat["p50"],
            "latency_p99_us": lat["p99"], "wall_s": s["timing"]["wall_s"]}


def _line(tag: str, r: dict[str, Any]) -> str:
    return (f"{tag}: misses {r['tick_misses']}/{r['ticks']} ({r['miss_pct']:.2f} %)  CPU {r['cpu_us_per_tick']:.0f} "
            f"us/tick  latency p50 {r['latency_p50_us']:.0f} p99 {r['latency_p99_us']:.0f} us")


def default_record(rows: list[dict[str, Any]]) -> dict[str, Any]:
    miss = [r["miss_pct"] for r in rows]
    rec = record("4s", "driver tick misses in the default real-time session (1 limb, 1 kHz)", runs=len(rows),
                 metric="summary.json timing.driver tick_misses / ticks per session (skipped deadlines), median and "
                        "min-max over sessions; p99 = median of the sessions' closed-loop latency p99 (us)",
                 unit="%", per_run=miss, p99=pct([r["latency_p99_us"] for r in rows], 50), p99_unit="us",
                 goal=f"misses < {GOAL_MISS_PCT} %", command=command_line(), details=rows,
                 notes=f"Each run: `{sea_hil_run_cmd('et', False)}` with the default [timing] (docs/timing.md); "
                       f"CPU per tick median {pct([r['cpu_us_per_tick'] for r in rows], 50):.0f} us (whole session).")
    rec["goal_met"] = rec["median"] < GOAL_MISS_PCT
    return rec


def lever_record(name: str, pairs: list[tuple[dict[str, Any], dict[str, Any]]], base: str = "") -> dict[str, Any]:
    a = [p[0]["miss_pct"] for p in pairs]
    b = [p[1]["miss_pct"] for p in pairs]
    details = [{"pair": i + 1, **{f"off_{k}": v for k, v in x.items()}, **{f"on_{k}": v for k, v in y.items()}}
               for i, (x, y) in enumerate(pairs)]
    rec = record(f"4s-{name}{'-on-' + base if base else ''}", f"[timing] lever `{name}` ({_toml(LEVERS[name]).splitlines()[1:]}): tick misses",
                 runs=len(pairs), metric="tick misses % with the lever (B) per pair; baseline = all levers off (A)",
                 unit="%", per_run=b, p99=pct([p[1]["latency_p99_us"] for p in pairs], 50), baseline=pct(a, 50),
                 baseline_label=f"all [timing] levers off{' but ' + base if base else ''}, same pairs", goal="(lever A/B)", command=command_line(),
                 details=details,
                 notes="CPU per tick off/on: " + ", ".join(f"{x['cpu_us_per_tick']:.0f}/{y['cpu_us_per_tick']:.0f}"
                                                            for x, y in pairs) + " us")
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=3)
    ap.add_argument("--levers", default="", help=f"comma-separated A/B levers: {','.join(LEVERS)}")
    ap.add_argument("--pairs", type=int, default=2, help="A/B pairs per lever (default 2)")
    ap.add_argument("--base", default="", help="A side = all levers off plus this lever (default: all off); B = A "
                                               "plus each of --levers")
    ap.add_argument("--no-default", action="store_true", help="skip the default-config sessions (levers only)")
    ap.add_argument("--workdir", type=Path, help="keep the run directories here (default: a temporary directory)")
    args = ap.parse_args(argv)
    levers = [x for x in args.levers.split(",") if x]
    unknown = set(levers) - set(LEVERS)
    base_timing = {**OFF, **LEVERS.get(args.base, {})}
    if args.base and args.base not in LEVERS:
        unknown.add(args.base)
    if unknown:
        ap.error(f"unknown lever(s) {sorted(unknown)}; choose from {','.join(LEVERS)}")
    runs, pairs = (1, 1) if args.quick else (args.runs, args.pairs)
    records: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench-session-timing-") as tmp:
        base = args.workdir or Path(tmp)
        if not args.no_default:
            rows = []
            for i in range(runs):
                rows.append(session(base / f"default{i + 1}", None))
                print(_line(f"run {i + 1}/{runs} default", rows[-1]), flush=True)
            records.append(default_record(rows))
        for name in levers:
            done = []
            for i in range(pairs):
                off = session(base / f"{name}{i + 1}-off", base_timing)
                on = session(base / f"{name}{i + 1}-on", {**base_timing, **LEVERS[name]})
                print(_line(f"{name} pair {i + 1}/{pairs} off", off), flush=True)
                print(_line(f"{name} pair {i + 1}/{pairs} on ", on), flush=True)
                done.append((off, on))
            records.append(lever_record(name, done, args.base))
    emit(records, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

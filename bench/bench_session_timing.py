"""Figure 4s: driver tick misses and closed-loop latency of the default real-time session (`sea-hil run --controller
et --cycles 1 [--limbs N]`), each run beside its own host floor, and, with `--levers`, the `[timing]` levers measured
one by one in interleaved A/B pairs (docs/timing.md).

Run: python -m bench.bench_session_timing [--runs 3] [--limbs 1,2,4] [--floor-s 10] [--loaded] [--levers LEVER,...]
     [--pairs 2] [--json OUT]
Each run first measures the host's floor (the empty 1 kHz loop of `sea_hil.runtime.timer_floor`, `--floor-s` s at
the driver's `[timing] realtime_priority`, as `python -m bench.bench_timer_floor --runs 1 --duration 10` does), then
runs the session: its misses are judged against that floor (issue 33: <= floor + 0.1 % at 1 and 2 limbs, <= 1 % at
4; latency p50 <= 0.5 ms and p99 <= 1.5 ms at 1 limb, p99 <= 3 ms at 4). `--loaded`: every count again with one core
kept busy by a spin loop during both the floor and the session (the "loaded" column: reported, not bounded).
(levers: fifo, fifo-process, fifo-session; the busy-wait tail, GC in the slack, the switch interval and CPU pinning
were measured as no gain and removed, docs/timing.md)
A tick miss is a skipped driver deadline (a tick later than one whole period: summary.json `timing.driver`
`tick_misses` of `ticks`), not a merely late tick. Each session's CPU time (RUSAGE_CHILDREN: the run process, its
controller and recorder children) is divided by its driver ticks: CPU per tick. With `--levers`, every lever is
compared against the baseline with all levers off (`[timing]` of docs/timing.md), each pair run A then B, so load
drifts hit both alike; on a loaded machine only these paired differences mean something.
"""
from __future__ import annotations

import math
import resource
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench.benchlib import bench_args, command_line, cpu_loader, emit, pct, record, sea_hil_run, sea_hil_run_cmd
from sea_hil.config.loader import load_config
from sea_hil.runtime.timer_floor import measure_floor

GOAL_MISS_PCT = 0.1          # beyond the floor, at 1 and 2 limbs (issue 33)
GOAL_MISS_4_PCT = 1.0        # at 4 limbs
GOAL_P50_US, GOAL_P99_US = 500.0, 1500.0   # closed-loop latency at 1 limb
GOAL_P99_4_US = 3000.0       # closed-loop latency p99 at 4 limbs
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


def session(out: Path, timing: dict[str, Any] | None, limbs: int = 1, floor_s: float = 0.0) -> dict[str, Any]:
    """One default session of `limbs` limbs (with `timing` as its `[timing]` section, else the default config),
    after `floor_s` s of the host's floor (0: none): its figures."""
    extra: tuple[str, ...] = ("--limbs", str(limbs)) if limbs != 1 else ()
    if timing is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "timing.toml").write_text(_toml(timing), encoding="utf-8")
        extra += ("--config", str(out / "timing.toml"))
    floor = measure_floor(floor_s, load_config(None).timing.realtime_priority) if floor_s > 0 else None
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    s = sea_hil_run(out, controller="et", extra=extra)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    drv = s["timing"]["driver"]
    ticks, misses = int(drv["ticks"]), int(drv["tick_misses"])
    lat = s["timing"]["latency_us"]
    return {"limbs": limbs, "ticks": ticks, "tick_misses": misses,
            "miss_pct": 100.0 * misses / ticks if ticks else float("nan"),
            "floor_miss_pct": float(floor["miss_pct"]) if floor else float("nan"),
            "floor_lateness_p99_us": float(floor["lateness_us_p99"]) if floor else float("nan"),
            "cpu_us_per_tick": 1e6 * cpu_s / ticks if ticks else float("nan"),
            "cpu_us_per_limb_sample": 1e6 * cpu_s / (ticks * limbs) if ticks else float("nan"),
            "latency_p50_us": lat["p50"], "latency_p99_us": lat["p99"], "wall_s": s["timing"]["wall_s"],
            "verdict": s.get("verdict", {}).get("status", "?")}


def _line(tag: str, r: dict[str, Any]) -> str:
    floor = f" beside floor {r['floor_miss_pct']:.3f} %" if math.isfinite(r.get("floor_miss_pct", math.nan)) else ""
    return (f"{tag}: misses {r['tick_misses']}/{r['ticks']} ({r['miss_pct']:.3f} %){floor}  CPU "
            f"{r['cpu_us_per_tick']:.0f} us/tick  latency p50 {r['latency_p50_us']:.0f} p99 "
            f"{r['latency_p99_us']:.0f} us")


def _held(r: dict[str, Any]) -> bool:
    """This run holds issue 33's bounds for its limb count, judged beside its own floor."""
    floor = r["floor_miss_pct"] if math.isfinite(r["floor_miss_pct"]) else 0.0   # no floor measured: 0
    if r["limbs"] >= 4:
        return bool(r["miss_pct"] <= GOAL_MISS_4_PCT and r["latency_p99_us"] <= GOAL_P99_4_US)
    ok = r["miss_pct"] <= floor + GOAL_MISS_PCT
    if r["limbs"] == 1:
        ok = ok and r["latency_p50_us"] <= GOAL_P50_US and r["latency_p99_us"] <= GOAL_P99_US
    return bool(ok)


def _goal(limbs: int) -> str:
    if limbs >= 4:
        return f"misses <= {GOAL_MISS_4_PCT:g} %, latency p99 <= {GOAL_P99_4_US / 1e3:g} ms (every run)"
    lat = (f", latency p50 <= {GOAL_P50_US / 1e3:g} ms and p99 <= {GOAL_P99_US / 1e3:g} ms" if limbs == 1 else "")
    return f"misses <= the run's floor + {GOAL_MISS_PCT:g} %{lat} (every run)"


def _us(rows: list[dict[str, Any]], key: str, fmt: str = ".0f") -> str:
    return ", ".join(format(r[key], fmt) for r in rows)


def default_record(rows: list[dict[str, Any]], limbs: int = 1, loaded: bool = False) -> dict[str, Any]:
    """Figure 4s (1 limb), 4s-2l, 4s-4l ...; `-loaded`: one core kept busy, reported, not judged. The baseline is
    the median of the runs' floors (each run's own floor judges it)."""
    miss = [r["miss_pct"] for r in rows]
    floors = [r["floor_miss_pct"] for r in rows if math.isfinite(r["floor_miss_pct"])]
    fig = "4s" + (f"-{limbs}l" if limbs != 1 else "") + ("-loaded" if loaded else "")
    cmd = sea_hil_run_cmd("et", False) + (f" --limbs {limbs}" if limbs != 1 else "")
    rec = record(fig, f"driver tick misses in the default real-time session ({limbs} limb{'s' if limbs > 1 else ''},"
                      f" 1 kHz{', one core busy' if loaded else ''})", runs=len(rows),
                 metric="summary.json timing.driver tick_misses / ticks per session (skipped deadlines), median and "
                        "min-max over sessions; baseline = median of the same runs' host floors; p99 = median of "
                        "the sessions' closed-loop latency p99 (us)",
                 unit="%", per_run=miss, p99=pct([r["latency_p99_us"] for r in rows], 50), p99_unit="us",
                 baseline=pct(floors, 50) if floors else None,
                 baseline_label="host floor (empty 1 kHz loop) before each run" if floors else "",
                 goal="(loaded: reported, not bounded)" if loaded else _goal(limbs), command=command_line(),
                 details=rows,
                 notes=f"Each run: the host floor, then `{cmd}` with the default [timing] (docs/timing.md). Latency "
                       f"p50 {_us(rows, 'latency_p50_us')} us, p99 {_us(rows, 'latency_p99_us')} us; floors "
                       f"{_us(rows, 'floor_miss_pct', '.3f')} %; CPU per limb-sample (whole "
                       f"session, start-up included) median "
                       f"{pct([r['cpu_us_per_limb_sample'] for r in rows], 50):.0f} us.")
    rec["goal_met"] = None if loaded else all(_held(r) for r in rows)
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
    ap.add_argument("--limbs", default="1", help="comma-separated limb counts of the default sessions (default 1)")
    ap.add_argument("--floor-s", type=float, default=10.0, help="host floor before each default session, s (0: none)")
    ap.add_argument("--loaded", action="store_true", help="every count again with one core kept busy")
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
        floor_s = 1.0 if args.quick else args.floor_s
        for loaded in (False, True) if args.loaded else (False,):
            for limbs in ([] if args.no_default else [int(x) for x in args.limbs.split(",") if x]):
                rows = []
                with cpu_loader(loaded):
                    for i in range(runs):
                        tag = f"{limbs}l{'-loaded' if loaded else ''}-{i + 1}"
                        rows.append(session(base / tag, None, limbs, floor_s))
                        print(_line(f"run {i + 1}/{runs} {limbs} limb(s){' loaded' if loaded else ''}", rows[-1]),
                              flush=True)
                records.append(default_record(rows, limbs, loaded))
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

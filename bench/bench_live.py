"""Figure 8: what the live view costs the 1 kHz loops: real-time sessions with and without `--foxglove`.

Run: python -m bench.bench_live [--runs 3] [--controller et] [--json OUT]
Each run is a pair of real-time `sea-hil run --controller et --cycles 1` sessions, one plain and one with
`--foxglove 0 --foxglove-wait` watched by a client subscribed to every live channel (bench/foxglove_ws_client.py, the
test suite's independent client, at nice 10: what a Foxglove app with the shipped layout open costs). The
order alternates per pair so a drift in machine load does not favour one side. Per session: closed-loop latency p99
(summary.json `latency_us`, the edge's state k published -> setpoint(k) applied) and driver tick misses (the
plant's `plant_overruns` of `plant_ticks`, MCAP metadata `sea-hil.final`), and the CPU seconds the whole session
used (RUSAGE_CHILDREN: run + recorder + controller). Goal (issue 18): with the live view, latency p99 and tick
misses within 10 % of without (tick misses: or no more than without).
"""
from __future__ import annotations

import asyncio
import json
import os
import re
import resource
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from bench.benchlib import REPO, bench_args, command_line, emit, record, sea_hil_run
from bench.foxglove_ws_client import receive
from bench.sessionwatch import watch_run
from sea_hil.errors import SeaHilError
from sea_hil.live.channels import CHANNELS, END_MESSAGE
from sea_hil.recorder.reader import read_session

GOAL_RATIO = 1.10
LOADED_MISS_PCT = 1.0   # a quiet machine misses < 0.1 % (figure 4); a baseline above 1 % is not a fair baseline
URL = re.compile(r"Foxglove live view: (ws://\S+)")


def _client(url: str, nice: int, timeout_s: float, result: dict[str, Any]) -> threading.Thread:
    """The client, in a thread of this process lowered to `nice` (a viewer on this machine is background work)."""
    def run() -> None:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)   # Linux: per-thread nice
        try:
            res = asyncio.run(receive(url, set(CHANNELS), end_message=END_MESSAGE, timeout_s=timeout_s))
        except (TimeoutError, OSError, SeaHilError) as err:   # a stalled session's server may vanish
            result.update(live_messages=0, live_ended=False, live_error=str(err))
            return
        result.update(live_messages=sum(len(v) for v in res.messages.values()), live_ended=res.ended)
    t = threading.Thread(target=run, name="foxglove-client", daemon=True)
    t.start()
    return t


def _session(out: Path, controller: str, live: bool, client_nice: int = 10, timeout_s: float = 300.0,
             stall_s: float = 30.0) -> dict[str, Any]:
    """One real-time session (with a subscribed client when `live`); its figures, or its stall (`status`)."""
    cmd = [sys.executable, "-m", "sea_hil.cli", "run", "--controller", controller, "--cycles", "1", "--out",
           str(out), *(["--foxglove", "0", "--foxglove-wait"] if live else [])]
    got: dict[str, Any] = {}
    clients: list[threading.Thread] = []
    cpu0 = _children_cpu_s()
    res = watch_run(cmd, out, cwd=REPO, stall_s=stall_s, timeout_s=timeout_s, find=URL if live else None,
                    on_found=lambda url: clients.append(_client(url, client_nice, timeout_s, got)))
    for t in clients:
        t.join(30.0)
    cpu_s = _children_cpu_s() - cpu0   # the whole session: run, its recorder and controller processes (reaped)
    if res.status != "ok":   # reported as such, with the stacks of every process of a stalled session
        print(f"session {out.name} {res.status} (exit {res.returncode}) after {res.wall_s:.0f} s; last progress: "
              f"{res.last_progress!r}; dumps: {res.dumps}", flush=True)
        return {"live": live, "status": res.status, "returncode": res.returncode, "last_progress": res.last_progress,
                "dumps": str(res.dumps) if res.dumps else "", "stderr_tail": res.stderr_tail[-600:], **got}
    if live and not got:
        raise SeaHilError(f"{' '.join(cmd)}: no live view address printed")
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    final = read_session(out / "session.mcap").metadata.get("sea-hil.final", {})
    ticks, overruns = int(final.get("plant_ticks", 0)), int(final.get("plant_overruns", 0))
    t = s["timing"]   # wall-time-derived fields (docs/session.md)
    return {"live": live, "status": "ok", "p99_us": t["latency_us"]["p99"], "p50_us": t["latency_us"]["p50"],
            "samples": t["latency_samples"], "plant_ticks": ticks, "plant_overruns": overruns,
            "miss_pct": 100.0 * overruns / ticks if ticks else float("nan"),
            "edge_loop_overruns": t["edge"]["loop_overruns"], "wall_s": t["wall_s"], "cpu_s": cpu_s, **got}


def _children_cpu_s() -> float:
    """CPU seconds (user + system) of this process's reaped descendants."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _median(vals: list[float]) -> float:
    v = sorted(vals)
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def live_records(details: list[dict[str, Any]], command: str) -> list[dict[str, Any]]:
    """Figures over the sessions that completed; stalled or failed ones are counted in the notes (and listed, with
    their dumps, in `details`). With no completed session on a side the comparison is not judged."""
    done = [d for d in details if d.get("status", "ok") == "ok"]
    on = [d for d in done if d["live"]] or [{"p99_us": float("nan"), "miss_pct": float("nan"), "cpu_s": float("nan")}]
    off = [d for d in done if not d["live"]] or [{"p99_us": float("nan"), "miss_pct": float("nan"),
                                                   "cpu_s": float("nan")}]
    bad = [d for d in details if d.get("status", "ok") != "ok"]
    p99_on, p99_off = [d["p99_us"] for d in on], [d["p99_us"] for d in off]
    miss_on, miss_off = [d["miss_pct"] for d in on], [d["miss_pct"] for d in off]
    # a baseline that already misses ticks means a loaded machine: the comparison is then not judged
    judged = _median(miss_off) < LOADED_MISS_PCT   # False for NaN (no completed baseline)
    lat_ok = _median(p99_on) <= GOAL_RATIO * _median(p99_off) if judged else None
    miss_ok = _median(miss_on) <= GOAL_RATIO * _median(miss_off) if judged else None
    note = ("Pairs of real-time sessions, alternating order; with = `--foxglove 0 --foxglove-wait` and a client "
            "subscribed to every live channel, in a thread at nice 10 (--client-nice) of the benchmark process; the "
            "server runs in the SCHED_IDLE recorder process.")
    if bad:
        note += (f" {len(bad)} of {len(details)} sessions did not complete ("
                 + ", ".join(f"pair {d.get('pair')} {'with' if d['live'] else 'without'}: {d['status']}" for d in bad)
                 + "; stacks in their stall-dumps.txt); the figures are over the completed ones.")
    if not judged:
        note += (f" NOT JUDGED (provisional): the sessions without the live view already missed "
                 f"{_median(miss_off):.1f} % of the driver ticks (>= {LOADED_MISS_PCT} %: the machine was loaded), "
                 "so the with/without difference is within the noise; re-run in a quiet window.")
    lat = record("8a", "live view cost: closed-loop latency p99 with --foxglove (baseline: without)", runs=len(on),
                 metric="per-session closed-loop latency p99 (summary.json latency_us), median over sessions",
                 unit="us", per_run=p99_on, p99=max(p99_on), baseline=_median(p99_off),
                 baseline_label="without --foxglove", goal="ratio <= 1.10", goal_met=lat_ok, command=command,
                 details=details, notes=note)
    miss = record("8b", "live view cost: driver tick misses with --foxglove (baseline: without)", runs=len(on),
                  metric="plant_overruns / plant_ticks per session (MCAP sea-hil.final), median over sessions",
                  unit="%", per_run=miss_on, p99=max(miss_on), baseline=_median(miss_off),
                  baseline_label="without --foxglove", goal="ratio <= 1.10 (or no more than without)",
                  goal_met=miss_ok, command=command, notes=note)
    cpu_on, cpu_off = [d["cpu_s"] for d in on], [d["cpu_s"] for d in off]
    cpu = record("8c", "live view cost: CPU s of a whole session with --foxglove (baseline: without)", runs=len(on),
                 metric="user + system CPU s of `sea-hil run` and its child processes per session (the watching "
                        "client excluded), median over sessions", unit="CPU s", per_run=cpu_on, p99=max(cpu_on),
                 baseline=_median(cpu_off), baseline_label="without --foxglove", goal="(informative)",
                 command=command, notes="Less sensitive to other load on the machine than 8a/8b: the extra work the "
                                        "live view does, all of it in the SCHED_IDLE recorder process.")
    return [lat, miss, cpu]


def replay_cost(mcap: Path, repeats: int = 5) -> dict[str, Any]:
    """CPU cost of the live view itself (LiveView.feed + LiveServer.publish, no client), replaying a recording: the
    work that would take the nodes' GIL if it were served from the `run` process (best of `repeats`)."""
    from sea_hil.config.live import LiveConfig
    from sea_hil.live.server import LiveServer
    from sea_hil.live.view import LiveView
    data = read_session(mcap)
    recs = sorted(((m.log_time_ns, t, m.payload) for t, ms in data.messages.items() for m in ms), key=lambda r: r[0])
    samples = [m.payload["sample_t_ns"] for m in data.messages["/zenoh/state"]]
    span_s = (max(samples) - min(samples)) / 1e9   # simulated seconds: in real time, seconds of session
    srv = LiveServer(LiveConfig(port=0))
    best_view = best_pub = float("inf")
    try:
        for _ in range(repeats):
            view = LiveView(bitrate_bps=1_000_000)
            t0 = time.process_time()
            out = [m for t, topic, p in recs for m in view.feed(topic, t, p)]
            t1 = time.process_time()
            for m in out:
                srv.publish(m)
            best_view, best_pub = min(best_view, t1 - t0), min(best_pub, time.process_time() - t1)
    finally:
        srv.close()
    return {"records": len(recs), "live_messages": len(out), "simulated_s": span_s,
            "view_us_per_record": 1e6 * best_view / len(recs), "publish_us_per_message": 1e6 * best_pub / len(out),
            "cpu_ms_per_s": 1e3 * (best_view + best_pub) / span_s}


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=3)
    ap.add_argument("--controller", choices=("et", "tt"), default="et")
    ap.add_argument("--client-nice", type=int, default=10, help="nice of the watching client's thread (default 10)")
    ap.add_argument("--workdir", type=Path, help="keep the run directories here (default: a temporary directory, "
                                                  "kept when a session stalled)")
    ap.add_argument("--stall-s", type=float, default=30.0, metavar="S",
                    help="a session whose simulated time and setpoints do not advance for S s is a stall (default 30)")
    args = ap.parse_args(argv)
    runs = 1 if args.quick else args.runs
    details: list[dict[str, Any]] = []
    base = args.workdir or Path(tempfile.mkdtemp(prefix="bench-live-"))
    for i in range(runs):
        for live in ((False, True) if i % 2 == 0 else (True, False)):
            d = _session(base / f"pair{i + 1}-{'live' if live else 'plain'}", args.controller, live,
                         args.client_nice, stall_s=args.stall_s)
            details.append({"pair": i + 1, **d})
            if d["status"] == "ok":
                print(f"pair {i + 1}/{runs} {'with' if live else 'without'} --foxglove: p99 {d['p99_us']:.0f} us  "
                      f"tick misses {d['plant_overruns']}/{d['plant_ticks']}"
                      + (f"  live messages {d.get('live_messages', 0)}" if live else ""), flush=True)
    lock = base / "lockstep"
    sea_hil_run(lock, controller=args.controller, lockstep=True)
    cost = replay_cost(lock / "session.mcap")
    if args.workdir is None and all(d["status"] == "ok" for d in details):
        shutil.rmtree(base, ignore_errors=True)
    elif args.workdir is None:
        print(f"run directories (with the stalled sessions' dumps) kept in {base}", flush=True)
    print(f"live view replay: {cost['view_us_per_record']:.2f} us per recorded message, "
          f"{cost['publish_us_per_message']:.1f} us per live message, {cost['cpu_ms_per_s']:.1f} ms CPU per s", flush=True)
    recs = live_records(details, command_line())
    recs.append(record("8d", "live view CPU per second of session (replay of a lockstep recording, no client)", runs=1,
                       metric="process_time of LiveView.feed + LiveServer.publish over the recording / its "
                              "simulated seconds, best of 5", unit="ms CPU/s", per_run=[cost["cpu_ms_per_s"]], p99=float("nan"),
                       goal="(informative)", command=command_line(), details=[cost],
                       notes="What serving from the `run` process would add to the nodes' GIL; served from the "
                             "recorder process it runs on idle CPU time instead."))
    emit(recs, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

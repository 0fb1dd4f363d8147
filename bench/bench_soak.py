"""Figure 10: soak, a long real-time session: memory growth, lost CAN frames, dropped Zenoh messages, recording
completeness.

Run: python -m bench.bench_soak --minutes 10 [--sample-s 1] [--workdir DIR] [--json OUT]
One real-time `sea-hil run --controller et --cycles N` (N walking cycles of `trajectory.period_s` covering the
minutes), watched for stalls (bench/sessionwatch.py). While the controller runs, every process of the session
(`run`: plant + edge + recorder taps; the controller child; the recorder child) is sampled every `--sample-s`
(psutil: RSS, user + system CPU). Afterwards the MCAP file is read back in one constant-memory pass
(`sea_hil.recorder.reader.read_session(path, on_message=...)`). Reported:
- RSS growth per process after the first minute: median RSS of the last 10 samples before the controller ended
  minus the median of the samples in [60 s, 70 s) (and the least-squares slope over t >= 60 s, MB/min);
- lost CAN frames: recorded `/can/feedback` frames against 3 x (driver ticks + 1) (3 frames per sample, one limb),
  recorded `/can/command` frames against the edge's VOLTAGE_CMD count, frames the DBC rejected (the
  recorder's sequence-gap count is reported beside: it also counts samples the edge did not answer);
- dropped Zenoh messages: setpoints the controller sent (its final stats) that the host's session, where the edge
  and the recorder's tap are, did not receive (recorded count); the states the controller skipped are reported;
- recording completeness: file complete and closed in order, writer/recorder drops 0, per-topic counts read back
  equal to the writer's counters, recorded `/zenoh/state` equal to the edge's published states and recorded
  `/zenoh/setpoint` equal to the controller's sent setpoints, both with contiguous sequence numbers.
Goal (issue 19): RSS growth < 5 MB per process after the first minute, 0 missed CAN frames, 0 lost recorder
messages. The post-run phase (`run` reading the whole file back for summary.json and figures) is reported apart:
its peak RSS grows with the session length by design of the report, not by a leak.
"""
from __future__ import annotations

import json
import math
import shutil
import sys
import tempfile
import time
from collections import defaultdict
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import psutil

from bench.benchlib import REPO, bench_args, command_line, emit, record
from bench.sessionwatch import watch_run
from sea_hil.config.loader import load_config
from sea_hil.recorder.reader import RecordedMessage, read_session

GOAL_RSS_MB = 5.0
FIRST_MINUTE_S = 60.0


def _role(cmdline: list[str]) -> str:
    cmd = " ".join(cmdline)
    if "sea_hil.recorder.process" in cmd:
        return "recorder"
    return "controller" if " controller " in f" {cmd} " else "other"


class Sampler:
    """`tick(proc)`: RSS and CPU of `proc` ("run") and its children, by role, while the controller runs."""

    def __init__(self) -> None:
        self.t0 = time.monotonic()
        self.samples: dict[str, list[tuple[float, float, float]]] = defaultdict(list)  # role -> (t_s, rss_mb, cpu_s)
        self.controller_seen = self.controller_ended = False
        self.post_peak_mb = 0.0   # `run` after the controller ended (summary, figures)

    def tick(self, proc: Any) -> None:
        t = time.monotonic() - self.t0
        try:
            top = psutil.Process(proc.pid)
            procs = {"run": top, **{_role(c.cmdline()): c for c in top.children(recursive=True)}}
        except psutil.Error:
            return
        alive = "controller" in procs
        self.controller_seen |= alive
        if self.controller_seen and not alive:
            self.controller_ended = True
        for role, p in procs.items():
            try:
                rss_mb, cpu = p.memory_info().rss / 2**20, sum(p.cpu_times()[:2])
            except psutil.Error:
                continue
            if self.controller_ended:
                if role == "run":
                    self.post_peak_mb = max(self.post_peak_mb, rss_mb)
            elif role != "other":
                self.samples[role].append((t, rss_mb, cpu))

    def growth(self) -> dict[str, dict[str, float]]:
        out = {}
        for role, s in self.samples.items():
            arr = np.array(s)
            after = arr[arr[:, 0] >= FIRST_MINUTE_S]
            ref = after[after[:, 0] < FIRST_MINUTE_S + 10.0]
            if len(after) < 20 or not len(ref):
                out[role] = {"growth_mb": math.nan, "slope_mb_per_min": math.nan, "rss_end_mb": float(arr[-1, 1])}
                continue
            slope = float(np.polyfit(after[:, 0] / 60.0, after[:, 1], 1)[0])
            cpu_pct = 100.0 * (arr[-1, 2] - arr[0, 2]) / max(arr[-1, 0] - arr[0, 0], 1e-9)
            out[role] = {"growth_mb": float(np.median(after[-10:, 1]) - np.median(ref[:, 1])),
                         "slope_mb_per_min": slope, "rss_at_1min_mb": float(np.median(ref[:, 1])),
                         "rss_end_mb": float(np.median(after[-10:, 1])), "rss_max_mb": float(arr[:, 1].max()),
                         "cpu_pct": cpu_pct, "samples": len(arr)}
        return out


def recording_check(mcap: Path) -> dict[str, Any]:
    """One pass over the file: per-topic counts, sequence gaps of the Zenoh streams, against the counters."""
    counts: dict[str, int] = defaultdict(int)
    seqs: dict[str, list[int]] = {"/zenoh/state": [], "/zenoh/setpoint": []}
    finals: dict[str, dict[str, Any]] = {}
    limit_faults: list[str] = []

    def on_message(topic: str, m: RecordedMessage) -> None:
        counts[topic] += 1
        if topic in seqs:   # an edge-trigger state (EVENT_STATE) numbers its events: its `seq` is the sample's
            seqs[topic].append(int(m.payload.get("event_seq", m.payload["seq"])))
        elif topic == "/stats" and m.payload.get("final") is True:
            finals[str(m.payload.get("node"))] = m.payload
        elif topic == "/log/faults" and "_LIMIT" in str(m.payload.get("message", "")):
            limit_faults.append(f"{m.log_time_ns}: {m.payload.get('message')}")   # the drive left a soft limit

    data = read_session(mcap, on_message=on_message)
    final, edge, ctl = data.metadata.get("sea-hil.final", {}), finals.get("edge", {}), finals.get("controller", {})
    commands_sent = sum(int(edge.get(k, 0)) for k in ("commands_sent", "arrival_commands"))   # VOLTAGE_CMDs
    writer_counts = {k.split(".", 1)[1]: int(v) for k, v in final.items() if k.startswith("messages.")}

    def gaps(v: list[int]) -> int:
        v = sorted(v)
        return sum(b - a - 1 for a, b in pairwise(v) if b > a + 1) + (v[0] - 1 if v else 0)
    ticks = int(final.get("plant_ticks", 0))
    # setpoints the edge never received either (its sequence tracker's `seq_lost`, beside the recorder's tap in the
    # host's Zenoh session) were dropped on the way to the host (figure 10c), not by the recorder
    host_lost = max(0, int(edge.get("seq_lost", 0)))
    out: dict[str, Any] = {"complete": data.complete, "closed_by": final.get("closed_by", ""), "messages": sum(counts.values()),
           "writer_dropped": int(final.get("dropped", -1)), "write_errors": int(final.get("write_errors", -1)),
           "recorder_dropped_ops": int(final.get("recorder_dropped_ops", -1)),
           "topic_count_mismatches": sum(counts.get(t, 0) != n for t, n in writer_counts.items()),
           "can_seq_gaps": int(final.get("can_frames_missed", -1)), "can_rejected": int(final.get("can_rejected", -1)),
           "plant_ticks": ticks, "plant_overruns": int(final.get("plant_overruns", 0)),
           "can_feedback_short": 3 * (ticks + 1) - counts.get("/can/feedback", 0),
           "can_commands_sent": commands_sent, "can_command_short": commands_sent - counts.get("/can/command", 0),
           "states_published": int(edge.get("uplink_msgs", -1)), "states_recorded": counts.get("/zenoh/state", 0),
           "state_seq_gaps_recorded": gaps(seqs["/zenoh/state"]),
           "setpoints_sent": int(ctl.get("setpoints_sent", -1)), "setpoints_recorded": counts.get("/zenoh/setpoint", 0),
           "setpoint_seq_gaps_recorded": gaps(seqs["/zenoh/setpoint"]), "setpoints_lost_before_host": host_lost,
           "zenoh_down_dropped": int(ctl.get("setpoints_sent", 0)) - counts.get("/zenoh/setpoint", 0),
           "controller_states_skipped": int(ctl.get("state_seq_lost", -1)),
           "drive_limit_faults": len(limit_faults), "first_limit_fault": limit_faults[0] if limit_faults else ""}
    out["recorder_lost"] = (out["writer_dropped"] + out["recorder_dropped_ops"] + out["write_errors"]
                            + out["topic_count_mismatches"] + abs(out["states_published"] - out["states_recorded"])
                            + abs(out["setpoints_sent"] - host_lost - out["setpoints_recorded"])
                            + out["state_seq_gaps_recorded"] + max(0, out["setpoint_seq_gaps_recorded"] - host_lost)
                            + (0 if out["complete"] and
                                                                    out["closed_by"] == "close" else 1))
    return out


def soak_records(growth: dict[str, dict[str, float]], rec: dict[str, Any], minutes: float, status: str,
                 post_peak_mb: float, command: str) -> list[dict[str, Any]]:
    roles = sorted(growth)
    worst = max((growth[r]["growth_mb"] for r in roles), default=math.nan)
    note = ("One real-time `sea-hil run --controller et` session; RSS sampled per process while the controller "
            "ran (psutil). Per process: " + "; ".join(
                f"{r} {growth[r]['growth_mb']:+.2f} MB (slope {growth[r]['slope_mb_per_min']:+.3f} MB/min, "
                f"{growth[r].get('rss_at_1min_mb', math.nan):.0f} -> {growth[r]['rss_end_mb']:.0f} MB, "
                f"CPU {growth[r].get('cpu_pct', math.nan):.0f} %)" for r in roles)
            + f". After the session, `run` reads the whole file for its report: peak RSS {post_peak_mb:.0f} MB. "
            f"Session status: {status}. Drive soft-limit faults logged: {rec.get('drive_limit_faults', 0)} (a soft-limit "
            "fault is left to the operator: the drive stays at 0 V from then on, the message flows go on)"
            + (f", the first {rec['first_limit_fault']}" if rec.get("first_limit_fault") else "") + ".")
    rss = record("10a", f"soak {minutes:g} min: RSS growth per process after the first minute", runs=1,
                 metric="max over processes of (median RSS of the last 10 samples - median over [60 s, 70 s))",
                 unit="MB", per_run=[worst], p99=float("nan"), goal=f"< {GOAL_RSS_MB:g} MB per process",
                 goal_met=bool(status == "ok" and worst < GOAL_RSS_MB), command=command,
                 details=[{"process": r, **growth[r]} for r in roles], notes=note)
    lost = (rec.get("can_rejected", 0) + abs(rec.get("can_feedback_short", -1))
            + abs(rec.get("can_command_short", -1)))
    can = record("10b", f"soak {minutes:g} min: lost CAN frames", runs=1,
                 metric="recorded vs sent: /can/feedback against 3 x (driver ticks + 1), /can/command against the "
                        "edge's VOLTAGE_CMDs; + frames the DBC rejected", unit="frames",
                 per_run=[lost], p99=float("nan"), goal="0", goal_met=bool(status == "ok" and lost == 0),
                 command=command, details=[rec], notes=f"{rec.get('plant_ticks', 0)} driver ticks, "
                 f"{rec.get('plant_overruns', 0)} overruns (a late tick is skipped, not a lost frame). The recorder's "
                 f"sequence-gap count ({rec.get('can_seq_gaps', 0)}) also counts the feedback samples the edge did "
                 "not answer (a VOLTAGE_CMD carries the seq of the sample it answers; none is sent while setpoints "
                 "are stale), so it is not a loss count.")
    zen = rec.get("zenoh_down_dropped", -1)
    zrec = record("10c", f"soak {minutes:g} min: dropped Zenoh messages", runs=1,
                  metric="setpoints the controller sent that did not reach the host's Zenoh session (recorded there, "
                         "beside the edge)", unit="messages", per_run=[zen], p99=float("nan"), goal="0 (informative)",
                  goal_met=None, command=command,
                  notes=f"States the controller skipped: {rec.get('controller_states_skipped')} (its newest-only "
                        "receive overwrites states it has not read yet; its stats do not separate these from losses).")
    rl = rec.get("recorder_lost", -1)
    comp = record("10d", f"soak {minutes:g} min: lost recorder messages (recording completeness)", runs=1,
                  metric="drops + write errors + per-topic count mismatches + published-vs-recorded Zenoh "
                         "differences + sequence gaps in the file (+1 if not complete and closed); setpoints the "
                         "edge never received either (dropped before the host, figure 10c) are not counted",
                  unit="messages", per_run=[rl], p99=float("nan"), goal="0",
                  goal_met=bool(status == "ok" and rl == 0), command=command,
                  notes=f"{rec.get('messages', 0)} messages read back; complete={rec.get('complete')}, "
                        f"closed_by={rec.get('closed_by')}.")
    return [rss, can, zrec, comp]


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=1)
    ap.add_argument("--minutes", type=float, default=10.0, help="session length (default 10)")
    ap.add_argument("--sample-s", type=float, default=1.0, help="sampling period of the processes (about)")
    ap.add_argument("--workdir", type=Path, help="keep the run directory here (default: temporary, kept on failure)")
    ap.add_argument("--tracemalloc", action="store_true",
                    help="leak finder: run `run` under tracemalloc (bench/studies/soak_tracemalloc.py) and write the "
                         "allocations grown between minute 1 and the end of the session to tracemalloc.txt")
    args = ap.parse_args(argv)
    period_s = load_config(None).trajectory.period_s
    minutes = 0.2 if args.quick else args.minutes
    cycles = max(1, math.ceil(minutes * 60.0 / period_s))
    base = args.workdir or Path(tempfile.mkdtemp(prefix="bench-soak-"))
    out = base / "soak"
    run_args = ["run", "--controller", "et", "--cycles", str(cycles), "--out", str(out)]
    cmd = [sys.executable, "-m", "sea_hil.cli", *run_args]
    if args.tracemalloc:
        cmd = [sys.executable, "-m", "bench.studies.soak_tracemalloc", str(out / "tracemalloc.txt"),
               str(FIRST_MINUTE_S), str(minutes * 60.0), "--", *run_args]
    sampler = Sampler()
    # the post-run phase prints nothing: the recorder child drains its backlog, then `run` reads the file back
    post_s = 1800.0 + 240.0 * minutes
    res = watch_run(cmd, out, cwd=REPO, stall_s=60.0, silent_s=post_s, timeout_s=3 * 60 * minutes + post_s,
                    on_tick=sampler.tick)
    print(f"session {res.status} in {res.wall_s:.0f} s (exit {res.returncode}); last progress {res.last_progress!r}",
          flush=True)
    (out / "processes.json").write_text(json.dumps(sampler.samples), encoding="utf-8")   # (t_s, rss_mb, cpu_s)
    rec = recording_check(out / "session.mcap") if (out / "session.mcap").exists() else {}
    growth = sampler.growth()
    for role, g in sorted(growth.items()):
        print(f"{role:10s} RSS growth after 1 min {g['growth_mb']:+.2f} MB  slope {g['slope_mb_per_min']:+.3f} MB/min"
              f"  end {g['rss_end_mb']:.0f} MB", flush=True)
    print("recording:", json.dumps(rec), flush=True)
    emit(soak_records(growth, rec, minutes, res.status, sampler.post_peak_mb, command_line()), args.json)
    if args.workdir is None and res.status == "ok":
        shutil.rmtree(base, ignore_errors=True)
    elif args.workdir is None:
        print(f"run directory kept in {base} (dumps: {res.dumps})", flush=True)
    return 0 if res.status == "ok" else 1


if __name__ == "__main__":
    sys.exit(main())

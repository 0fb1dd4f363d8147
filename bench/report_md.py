"""Render BENCHMARKS.md from result records (see bench/benchlib.py): a summary table, then per-figure notes with
the metric definition, the reason and next lever for goals not met, and the detail tables."""
from __future__ import annotations

import math
from typing import Any

# Why a goal may be missed and what to try next; shown only for records with goal_met == False.
LEVERS = {
    "2": "The project path's newest-only receive wakes the controller's thread directly (`LatestSubscriber`: "
         "zenoh's thread puts into a SimpleQueue) and STATE / EVENT_STATE / SETPOINT go through one struct call each "
         "way; what is left over raw is the decode and validation of real payloads on both ends (docs/timing.md, "
         "'Zenoh hop'). The ratio varies run to run on this VM (each run now pings all modes in turn).",
    "3": "Issue 33's goal (p50 <= 0.5 ms, p99 <= 1.5 ms). Per stage (bench/studies/latency_stages.py, "
         "docs/timing.md 'Closed loop'): each process wakes cold for every state, so each stage costs several times "
         "its hot price. What is left: zenoh's own hops (uplink, downlink, 200-300 us each under load) and the "
         "controller's cold compute (~200 us CPU per state); handling in zenoh's threads saved nothing measurable.",
    "5": "ET's event count is now below 1/3 of TT's in every real-time run (setpoints are applied on arrival and "
         "the cycles start on the trajectory after the lead-in, docs/deviations.md section 8). What fails is the "
         "error bound: in steady state ET's knee error (held v_x between events) is ~1.5x TT's in this model, "
         "offline too (1.52x at eta 0.5, 1.38x at the paper's eta 0.3 with 348 events; docs/deviations.md "
         "section 6), so no eta meets both bounds; before the lead-in a start-up transient dominated both maxima "
         "and hid it. The trigger was not re-tuned to pass.",
    "4": "Python threads of plant, edge and Zenoh share one GIL and a 2-core machine; lateness tails come from GIL "
         "hand-off and scheduler pre-emption (the loaded row shows the effect of losing the second core). Next "
         "levers: run plant and edge in separate processes, SCHED_FIFO + CPU pinning, or move the 1 kHz loops to "
         "native code.",
    "6": "Every limb adds a 1 kHz edge thread and 4 CAN frames per ms that the python-can virtual bus deep-copies "
         "to every bus handle (cost grows ~N^2), all under one GIL. Next levers: one edge thread serving all node "
         "ids, a process per limb, SocketCAN with kernel filters.",
    "8": "The live view itself runs in the SCHED_IDLE recorder process (8d: its own CPU per simulated second); "
         "what remains on the nodes' cores is the watching client and the pipe to the recorder. Next levers: watch "
         "from another host (`--foxglove-host`), or send /live/tracking at a lower rate.",
    "7": "The recorder's JSON encoding and validation run in Python on the submitting thread. Next lever: a binary "
         "(e.g. protobuf/flatbuffer) channel encoding for /can/raw, or batching CAN frames per sample.",
}


def fmt(v: Any, unit: str = "") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        a = abs(v)
        s = f"{v:.3g}" if a < 10 else (f"{v:.1f}" if a < 1000 else f"{v:,.0f}")
    else:
        s = str(v)
    return f"{s} {unit}".strip()


def _met(r: dict[str, Any]) -> str:
    return {True: "**met**", False: "**not met**", None: "–"}[r.get("goal_met")]


def summary_table(records: list[dict[str, Any]]) -> list[str]:
    out = ["| fig | what | command | runs | median | p99 | min–max over runs | baseline (same run) | ratio | goal | "
           "met |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        if r.get("error"):
            out.append(f"| {r['figure']} | {r['title']} | `{r['command']}` | – | FAILED: {r['error']} | | | | | | |")
            continue
        u = r.get("unit", "")
        out.append(f"| {r['figure']} | {r['title']} | `{r['command']}` | {r['runs']} | {fmt(r['median'], u)} | "
                   f"{fmt(r.get('p99'), r.get('p99_unit', u))} | {fmt(r['min'])}–{fmt(r['max'], u)} | {fmt(r.get('baseline'), u)} | "
                   f"{fmt(r.get('ratio'))} | {r.get('goal', '')} | {_met(r)} |")
    return out


def detail_table(rows: list[dict[str, Any]]) -> list[str]:
    if not rows:
        return []
    keys: list[str] = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    out += ["| " + " | ".join(fmt(row.get(k)) for k in keys) + " |" for row in rows]
    return out


def figure_notes(r: dict[str, Any], machine: str = "") -> list[str]:
    out = [f"### Figure {r['figure']}: {r['title']}", ""]
    if r.get("error"):
        return out + [f"Failed: {r['error']}", ""]
    out.append(f"Metric: {r['metric']}. Unit: {r.get('unit', '')}. Runs: {r['runs']}. Measured {r['date']}"
               f"{' on ' + machine if machine else ''} (load average {r['host'].get('loadavg_1m')} at the start).")
    if r.get("baseline_label"):
        out.append(f"Baseline: {r['baseline_label']}.")
    if r.get("notes"):
        out.append(r["notes"])
    if r.get("goal_met") is False:
        lever = LEVERS.get(r["figure"].rstrip("abcd"), "")
        out.append(f"**Goal not met** ({r.get('goal', '')}). {lever}")
    out.append("")
    table = detail_table(r.get("details", []))
    return out + table + ([""] if table else [])


def _host_line(host: dict[str, Any]) -> str:
    return f"{host.get('hostname')} ({host.get('cpu')}, {host.get('cores')} cores, kernel {host.get('kernel')})"


def render(records: list[dict[str, Any]], *, preliminary: bool, total_s: float, header: str) -> str:
    """The markdown. A file re-rendered after `--only` holds figures of other runs, maybe of another machine: the
    header names every machine, and each figure's notes name its own when there is more than one."""
    hosts = [r["host"] for r in sorted(records, key=lambda r: str(r.get("date", "")), reverse=True) if r.get("host")]
    host = hosts[0] if hosts else {}
    machines = list(dict.fromkeys(_host_line(h) for h in hosts))
    lines = ["# Benchmarks", ""]
    if preliminary:
        lines += ["> **PRELIMINARY** — produced by `python -m bench.run_all --quick` (tiny sizes, one run, a machine "
                  "busy with other work). The numbers only show that every script runs; the figures are the ones "
                  "of a full `python -m bench.run_all` in a quiet window.", ""]
    lines += [header, "",
              f"Host{'s' if len(machines) > 1 else ''}: {'; '.join(machines) or _host_line(host)} (newest first; "
              f"each figure's notes name its machine when there are several), Python {host.get('python')}, "
              f"eclipse-zenoh {host.get('eclipse-zenoh')}, python-can {host.get('python-can')}, mcap "
              f"{host.get('mcap')}. The scripts of this run took {total_s:.0f} s.", "",
              "median / min–max are over the per-run values of each figure's metric; p99 is defined per figure "
              "(notes below). Every row is reproducible with the command beside it; `python -m bench.run_all` "
              "re-runs all of them and rewrites this file (`--quick` for a smoke run).", ""]
    lines += summary_table(records) + ["", "## Notes per figure", ""]
    for r in records:
        lines += figure_notes(r, _host_line(r["host"]) if len(machines) > 1 and r.get("host") else "")
    return "\n".join(lines).rstrip() + "\n"
